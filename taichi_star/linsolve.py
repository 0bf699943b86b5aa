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
    for all neighbour pairs, row-major, at `update_slot` from update_start[p]. The slots of the
    pattern itself (the diagonal and the given pairs) come first, `n_structural` of them; the
    fill-in's follow, which only the factorisation writes.
    """

    n_nodes: int
    order: np.ndarray
    slot: dict
    n_structural: int
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
    def pattern_slot(self) -> dict:
        """`slot` without the fill-in: (i, j) -> slot for the diagonal and the given pairs, the
        blocks an assembly may write (a pair it did not declare then fails as a KeyError, even
        where the elimination filled it in)."""
        return {pair: slot for pair, slot in self.slot.items() if slot < self.n_structural}

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
    n_structural = len(slot)

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
        n_structural=n_structural, pivot_slot=as_int(pivot_slot),
        neighbour_start=as_int(neighbour_start),
        neighbour_node=as_int(neighbour_node), lower_slot=as_int(lower_slot),
        upper_slot=as_int(upper_slot), update_start=as_int(update_start),
        update_slot=as_int(update_slot))


def _non_empty(values: np.ndarray) -> np.ndarray:
    """An index table with at least one entry (a field cannot be empty)."""
    return values if len(values) else np.zeros(1, dtype=np.int32)


class BlockElimination:
    """The numeric block LU and solve of an `EliminationPlan`, written once for two storages:
    `BlockSystem` (a unit is one instance, an entry one scalar) and `LaneBlocks` (a unit is a
    group of instances, an entry a ti.Vector holding one scalar of each). A subclass provides
    the plan's index tables (`tables`, a BlockSystem) and the storage: `block(u, slot)` and
    `put_block(u, slot, block)`, a 2×2 block as its four entries a00, a01, a10, a11
    (`entry(block, k)`, `block_of(a00, a01, a10, a11)`), `rhs_entry(u, node, k)` and
    `put_rhs_entry(u, node, k, value)`. Each entry is computed by the same operations in the
    same order in both: Taichi's 2×2 `@` (a[i,0]·b[0,j] + a[i,1]·b[1,j]) and `inverse()`
    (1/(a00·a11 − a01·a10) times the adjugate), so the two storages give the same bits."""

    @ti.func
    def product(self, x, y):
        """The 2×2 block product x·y."""
        return self.block_of(
            self.entry(x, 0) * self.entry(y, 0) + self.entry(x, 1) * self.entry(y, 2),
            self.entry(x, 0) * self.entry(y, 1) + self.entry(x, 1) * self.entry(y, 3),
            self.entry(x, 2) * self.entry(y, 0) + self.entry(x, 3) * self.entry(y, 2),
            self.entry(x, 2) * self.entry(y, 1) + self.entry(x, 3) * self.entry(y, 3))

    @ti.func
    def inverse(self, x):
        """The inverse of the 2×2 block x."""
        inverse_determinant = 1.0 / (self.entry(x, 0) * self.entry(x, 3)
                                     - self.entry(x, 1) * self.entry(x, 2))
        return self.block_of(inverse_determinant * self.entry(x, 3),
                             -inverse_determinant * self.entry(x, 1),
                             -inverse_determinant * self.entry(x, 2),
                             inverse_determinant * self.entry(x, 0))

    @ti.func
    def factor(self, u):
        """In-place block LU of unit u without pivoting (the pivots are 2×2 inverses)."""
        t = self.tables
        for p in range(t.n_nodes):
            pivot_inverse = self.inverse(self.block(u, t.pivot_slot[p]))
            self.put_block(u, t.pivot_slot[p], pivot_inverse)
            start = t.neighbour_start[p]
            count = t.neighbour_start[p + 1] - start
            for a in range(count):
                lower = t.lower_slot[start + a]
                self.put_block(u, lower, self.product(self.block(u, lower), pivot_inverse))
            update = t.update_start[p]
            for a in range(count):
                lower_block = self.block(u, t.lower_slot[start + a])
                for c in range(count):
                    target = t.update_slot[update + a * count + c]
                    upper_block = self.block(u, t.upper_slot[start + c])
                    self.put_block(u, target, self.block(u, target)
                                   - self.product(lower_block, upper_block))

    @ti.func
    def solve(self, u):
        """Overwrite unit u's right-hand side with the solution of its factored system (node
        numbering)."""
        t = self.tables
        for p in range(t.n_nodes):
            node = t.order[p]
            x0, x1 = self.rhs_entry(u, node, 0), self.rhs_entry(u, node, 1)
            for a in range(t.neighbour_start[p], t.neighbour_start[p + 1]):
                neighbour = t.neighbour_node[a]
                lower = self.block(u, t.lower_slot[a])
                self.put_rhs_entry(u, neighbour, 0, self.rhs_entry(u, neighbour, 0) - (
                    self.entry(lower, 0) * x0 + self.entry(lower, 1) * x1))
                self.put_rhs_entry(u, neighbour, 1, self.rhs_entry(u, neighbour, 1) - (
                    self.entry(lower, 2) * x0 + self.entry(lower, 3) * x1))
        for reverse in range(t.n_nodes):
            p = t.n_nodes - 1 - reverse
            node = t.order[p]
            v0, v1 = self.rhs_entry(u, node, 0), self.rhs_entry(u, node, 1)
            for a in range(t.neighbour_start[p], t.neighbour_start[p + 1]):
                upper = self.block(u, t.upper_slot[a])
                neighbour = t.neighbour_node[a]
                y0, y1 = self.rhs_entry(u, neighbour, 0), self.rhs_entry(u, neighbour, 1)
                v0 -= self.entry(upper, 0) * y0 + self.entry(upper, 1) * y1
                v1 -= self.entry(upper, 2) * y0 + self.entry(upper, 3) * y1
            pivot = self.block(u, t.pivot_slot[p])
            self.put_rhs_entry(u, node, 0, self.entry(pivot, 0) * v0 + self.entry(pivot, 1) * v1)
            self.put_rhs_entry(u, node, 1, self.entry(pivot, 2) * v0 + self.entry(pivot, 3) * v1)


@ti.data_oriented
class BlockSystem(BlockElimination):
    """Device copy of an EliminationPlan plus, per instance, the matrix blocks and right-hand
    side: `blocks` (batch, n_slots) 2×2 and `rhs` (batch, n_nodes) 2-vectors. After `factor`
    the blocks hold L (unit block-lower), U and the inverted pivot blocks, in place (a unit of
    `BlockElimination` is an instance)."""

    def __init__(self, plan: EliminationPlan, batch_size: int, arena: Optional[FieldArena] = None):
        """`arena`: where the fields go (an engine's); None: an arena of its own, finalized
        here."""
        own = arena is None
        arena = FieldArena() if own else arena
        self.plan = plan
        self.tables = self
        self.n_nodes = plan.n_nodes
        self.n_slots = plan.n_slots
        self.n_structural = plan.n_structural
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
    def entry(self, block, k):
        return block[k]

    @ti.func
    def block_of(self, a00, a01, a10, a11):
        return ti.Vector([a00, a01, a10, a11])

    @ti.func
    def block(self, b, slot):
        value = self.blocks[b, slot]
        return ti.Vector([value[0, 0], value[0, 1], value[1, 0], value[1, 1]])

    @ti.func
    def put_block(self, b, slot, block):
        self.blocks[b, slot] = ti.Matrix([[block[0], block[1]], [block[2], block[3]]])

    @ti.func
    def rhs_entry(self, b, node, k: ti.template()):
        return self.rhs[b, node][k]

    @ti.func
    def put_rhs_entry(self, b, node, k: ti.template(), value):
        self.rhs[b, node][k] = value


@ti.data_oriented
class LaneBlocks(BlockElimination):
    """The Newton systems of groups of `lanes` instances of a `BlockSystem`, laid out so that
    the CPU's vector units factor and solve them together: every entry of a group is a
    ti.Vector of its lanes' values (LLVM packs those into vector instructions), `blocks`
    (groups, n_slots, 4) and `rhs` (groups, n_nodes, 2). `gather` copies a group's instances'
    systems in, `scatter_solution` their solutions back; `factor` and `solve` (of
    `BlockElimination`, a unit being a group) give each lane the bits the instance's own
    factorisation and solve give."""

    def __init__(self, system: BlockSystem, groups: int, lanes: int, arena: FieldArena):
        self.tables = system
        self.system = system
        self.lanes = lanes
        self.blocks = arena.field(float, (groups, system.n_slots, 4), vector=lanes)
        self.rhs = arena.field(float, (groups, system.n_nodes, 2), vector=lanes)

    @ti.func
    def entry(self, block, k):
        return ti.Vector([block[k, lane] for lane in ti.static(range(self.lanes))])

    @ti.func
    def block_of(self, a00, a01, a10, a11):
        return ti.Matrix.rows([a00, a01, a10, a11])

    @ti.func
    def block(self, g, slot):
        return ti.Matrix.rows([self.blocks[g, slot, k] for k in ti.static(range(4))])

    @ti.func
    def put_block(self, g, slot, block):
        for k in ti.static(range(4)):
            self.blocks[g, slot, k] = self.entry(block, k)

    @ti.func
    def rhs_entry(self, g, node, k: ti.template()):
        return self.rhs[g, node, k]

    @ti.func
    def put_rhs_entry(self, g, node, k: ti.template(), value):
        self.rhs[g, node, k] = value

    @ti.func
    def gather(self, g, members):
        """Copy the systems of group g's instances (`members`, a ti.Vector of `lanes` instance
        numbers) into its lanes. The fill-in's slots, which no assembly writes (an instance's
        hold the zeros its assembly cleared), are zeroed without reading the instances: the
        copy reads eight instances' systems and is bound by the memory traffic."""
        system = self.system
        for slot in range(system.n_structural):
            for k in ti.static(range(4)):
                self.blocks[g, slot, k] = ti.Vector(
                    [system.blocks[members[lane], slot][k // 2, k % 2]
                     for lane in ti.static(range(self.lanes))])
        for slot in range(system.n_structural, system.n_slots):
            for k in ti.static(range(4)):
                self.blocks[g, slot, k] = ti.Vector([0.0] * self.lanes)
        for node in range(system.n_nodes):
            for k in ti.static(range(2)):
                self.rhs[g, node, k] = ti.Vector(
                    [system.rhs[members[lane], node][k] for lane in ti.static(range(self.lanes))])

    @ti.func
    def scatter_solution(self, g, members):
        """Copy each lane's solution back into its instance's right-hand side."""
        system = self.system
        for node in range(system.n_nodes):
            x = self.rhs[g, node, 0]
            y = self.rhs[g, node, 1]
            for lane in ti.static(range(self.lanes)):
                system.rhs[members[lane], node] = ti.Vector([x[lane], y[lane]])
