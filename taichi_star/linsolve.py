"""Block-sparse LU without pivoting on a fixed pattern, for the Newton systems of a batch.

The Newton matrix couples nodes through edges, bending triplets and the jet (hub row). Its
pattern is the same for every instance and every step, so the symbolic work is done once on the
host: a minimum-degree elimination order of the nodes (which condenses each limb and arc chain
onto the joints and the hub, with the hub eliminated late), the fill-in pattern, and the flat
list of block operations of the factorisation. The numeric factorisation and the solve are Taichi
functions that replay that list for one instance; each entry of the pattern is a 2×2 block (one
node's x, y against another's), stored in a field with a leading batch axis.

Every update of a field element is written as an explicit load and store: Taichi turns `+=` on
a global field into an atomic, which costs several times more on the CPU and is never needed
here (one thread owns one instance).

A band is the special case of a chain order; at the default topology (N = 193) this order costs
about 61 kFLOP per factorisation (`EliminationPlan.factor_flops`), against about 280 kFLOP for the
hub-bordered band of a reverse Cuthill–McKee order.
"""


from dataclasses import dataclass
from typing import Optional

import numpy as np
import taichi as ti

from .fields import FieldArena


@dataclass(frozen=True)
class EliminationPlan:
    """Host-side symbolic factorisation of a structurally symmetric node pattern.

    For pivot p (node order[p]): neighbours are the later nodes coupled to it after fill; their
    lower blocks A[i, k] and upper blocks A[k, i] live at `lower_slot`/`upper_slot` in
    [neighbour_start[p], neighbour_start[p + 1]); the Schur updates A[i, j] -= L[i, k] U[k, j]
    for all neighbour pairs, row-major, at `update_slot` from update_start[p].
    """

    n_nodes: int
    order: np.ndarray
    slot: dict
    pivot_slot: np.ndarray
    neighbour_start: np.ndarray
    neighbour_node: np.ndarray
    lower_slot: np.ndarray
    upper_slot: np.ndarray
    update_start: np.ndarray
    update_slot: np.ndarray

    @property
    def n_slots(self) -> int:
        return len(self.slot)

    @property
    def factor_flops(self) -> int:
        """Floating point operations of one numeric factorisation (2×2 block products = 8 FMA)."""
        n_neighbours = np.diff(self.neighbour_start)
        return int(16 * (n_neighbours ** 2).sum() + 16 * n_neighbours.sum() + 10 * self.n_nodes)


def minimum_degree_order(n_nodes: int, pairs) -> np.ndarray:
    """Greedy minimum-degree elimination order of the graph on n_nodes with edges `pairs`
    (ties broken by the lowest node number, so the order is deterministic)."""
    neighbours = [set() for _ in range(n_nodes)]
    for i, j in pairs:
        if i != j:
            neighbours[i].add(j)
            neighbours[j].add(i)
    remaining = set(range(n_nodes))
    order = []
    while remaining:
        node = min(remaining, key=lambda n: (len(neighbours[n]), n))
        remaining.remove(node)
        order.append(node)
        clique = neighbours[node]
        for i in clique:
            neighbours[i].discard(node)
            neighbours[i] |= clique - {i}
        neighbours[node] = set()
    return np.array(order, dtype=np.int64)


def plan_elimination(n_nodes: int, pairs, order=None) -> EliminationPlan:
    """Symbolic LU of the node pattern given by `pairs` (i, j) (made symmetric, diagonal added)
    under `order` (default: minimum degree)."""
    pairs = [(int(i), int(j)) for i, j in pairs]
    if order is None:
        order = minimum_degree_order(n_nodes, pairs)
    position = np.empty(n_nodes, dtype=np.int64)
    position[order] = np.arange(n_nodes)
    later = [set() for _ in range(n_nodes)]
    for i, j in pairs:
        if i != j:
            first, second = (i, j) if position[i] < position[j] else (j, i)
            later[first].add(second)
    slot = {}

    def slot_of(i, j):
        return slot.setdefault((i, j), len(slot))

    for node in range(n_nodes):
        slot_of(node, node)
    for i, j in pairs:
        slot_of(i, j)
        slot_of(j, i)

    pivot_slot, neighbour_start, neighbour_node = [], [0], []
    lower_slot, upper_slot, update_start, update_slot = [], [], [0], []
    for node in order:
        neighbours = sorted(later[node], key=lambda n: position[n])
        for a in neighbours:
            later[a] |= {b for b in neighbours if position[b] > position[a]}
        pivot_slot.append(slot_of(node, node))
        neighbour_node += neighbours
        lower_slot += [slot_of(i, node) for i in neighbours]
        upper_slot += [slot_of(node, i) for i in neighbours]
        update_slot += [slot_of(i, j) for i in neighbours for j in neighbours]
        neighbour_start.append(len(neighbour_node))
        update_start.append(len(update_slot))
    as_int = lambda values: np.array(values, dtype=np.int32)  # noqa: E731
    return EliminationPlan(
        n_nodes=n_nodes, order=np.asarray(order, dtype=np.int32), slot=slot,
        pivot_slot=as_int(pivot_slot), neighbour_start=as_int(neighbour_start),
        neighbour_node=as_int(neighbour_node), lower_slot=as_int(lower_slot),
        upper_slot=as_int(upper_slot), update_start=as_int(update_start),
        update_slot=as_int(update_slot))


def _non_empty(values: np.ndarray) -> np.ndarray:
    """An index table with at least one entry (a field cannot be empty)."""
    return values if len(values) else np.zeros(1, dtype=np.int32)


@ti.data_oriented
class BlockSystem:
    """Device copy of an EliminationPlan plus, per instance, the matrix blocks and right-hand
    side: `blocks` (batch, n_slots) 2×2 and `rhs` (batch, n_nodes) 2-vectors. After `factor`
    the blocks hold L (unit block-lower), U and the inverted pivot blocks, in place."""

    def __init__(self, plan: EliminationPlan, batch_size: int, arena: Optional[FieldArena] = None):
        """`arena`: where the fields go (an engine's); None: an arena of its own, finalized
        here."""
        own = arena is None
        arena = FieldArena() if own else arena
        self.plan = plan
        self.n_nodes = plan.n_nodes
        self.n_slots = plan.n_slots
        self.order = arena.index(_non_empty(plan.order))
        self.pivot_slot = arena.index(_non_empty(plan.pivot_slot))
        self.neighbour_start = arena.index(_non_empty(plan.neighbour_start))
        self.neighbour_node = arena.index(_non_empty(plan.neighbour_node))
        self.lower_slot = arena.index(_non_empty(plan.lower_slot))
        self.upper_slot = arena.index(_non_empty(plan.upper_slot))
        self.update_start = arena.index(_non_empty(plan.update_start))
        self.update_slot = arena.index(_non_empty(plan.update_slot))
        self.blocks = arena.batch_field(float, (batch_size, plan.n_slots), matrix=(2, 2))
        self.rhs = arena.batch_field(float, (batch_size, plan.n_nodes), vector=2)
        if own:
            arena.finalize()

    @ti.func
    def clear(self, b, blocks):
        """Zero rhs[b] and, if `blocks`, the matrix blocks of instance b."""
        if blocks:
            for s in range(self.n_slots):
                self.blocks[b, s] = ti.Matrix.zero(float, 2, 2)
        for n in range(self.n_nodes):
            self.rhs[b, n] = ti.Vector.zero(float, 2)

    @ti.func
    def factor(self, b):
        """In-place block LU of instance b without pivoting (the pivots are 2×2 inverses)."""
        for p in range(self.n_nodes):
            pivot_inverse = self.blocks[b, self.pivot_slot[p]].inverse()
            self.blocks[b, self.pivot_slot[p]] = pivot_inverse
            start = self.neighbour_start[p]
            count = self.neighbour_start[p + 1] - start
            for a in range(count):
                lower = self.lower_slot[start + a]
                self.blocks[b, lower] = self.blocks[b, lower] @ pivot_inverse
            update = self.update_start[p]
            for a in range(count):
                lower_block = self.blocks[b, self.lower_slot[start + a]]
                for c in range(count):
                    target = self.update_slot[update + a * count + c]
                    upper_block = self.blocks[b, self.upper_slot[start + c]]
                    self.blocks[b, target] = self.blocks[b, target] - lower_block @ upper_block

    @ti.func
    def solve(self, b):
        """Overwrite rhs[b] with the solution of the factored system (node numbering)."""
        for p in range(self.n_nodes):
            node = self.order[p]
            start = self.neighbour_start[p]
            for a in range(start, self.neighbour_start[p + 1]):
                neighbour = self.neighbour_node[a]
                lower_block = self.blocks[b, self.lower_slot[a]]
                self.rhs[b, neighbour] = self.rhs[b, neighbour] - lower_block @ self.rhs[b, node]
        for reverse in range(self.n_nodes):
            p = self.n_nodes - 1 - reverse
            node = self.order[p]
            value = self.rhs[b, node]
            for a in range(self.neighbour_start[p], self.neighbour_start[p + 1]):
                value -= self.blocks[b, self.upper_slot[a]] @ self.rhs[b, self.neighbour_node[a]]
            self.rhs[b, node] = self.blocks[b, self.pivot_slot[p]] @ value
