"""What a force term sees of the system it adds itself to: the `Assembly`.

A term never holds the engine. It receives one `Assembly` and asks it, on the host while it
builds its tables, for

- `capacity` and `topology`, `batch_field` (a field with a leading batch axis for its
  coefficients and histories) and `index` (an integer table on the device);
- `slot(i, j)`: where the 2×2 Jacobian block of nodes (i, j) is stored, and the slot tables
  `pair_slots` (edges) and `triplet_slots` (bending triplets) that `scatter_edge` and
  `scatter_triplet` read;

and in its `@ti.func`s, for instance b,

- `positions[b, n]`, `previous[b, n]`: node n at the current Newton iterate and at the step's
  start, m; `fire_time[b, m]`, `previous_fire_time[b, m]`: when actuator m fired last and the
  time before, s;
- the integrator's rates: `implicit_velocity(b, n, rate_gain)` and `rate_offset(...)` for any
  other quantity (the gain and offset of `integrators`);
- `primal_instance(b)`: in an engine with sensitivities, the simulated instance that b is a
  replica of (b itself for a simulated one; `replicated`: whether there are any replicas);
- the scatter of its residual and Jacobian: `add_residual(b, n, value)` for node n,
  `add_block(b, slot, value, jacobian)` for one block, `add_blocks` for a row of a slot table
  at once (all loaded before any is stored: on a GPU they are then in flight together), and for
  a term of one edge vector or of the two edge vectors of a triplet `scatter_edge` and
  `scatter_triplet`, which apply the incidence (∂/∂x_i = −∂/∂e) themselves.

The engine makes one `Assembly` from its state, linear system and integrator and hands it to
each term; a test can make one of a toy topology and assemble a single term on its own
(tests/unit/test_assembly.py). Every method is a plain load, add and store of what it is
given: a term assembled through it computes the same arithmetic as one written inline.
"""

import taichi as ti

KEEP_EXPANSION = 2
"""The `jacobian` argument of a simulated instance's assembly at its converged state in a
sensitive engine's tangent step (`engine.BatchEngine.tangent_step`): the Jacobian (it is
truthy), and a term that pairs linearly (`base.Term.pairs_linearly`) keeps the velocity
derivative it expands its replicas with (`Assembly.primal_instance`), for the pairs that leave
it out of their residuals (their difference: the term's `pair_difference`)."""


def distinct_rows(rows, element: str):
    """`rows` (lists of Jacobian slots, one element each), checked to repeat no slot within a
    row: `add_blocks` loads a row's blocks before it stores any, so a slot twice in a row would
    keep only its last sum (an element whose nodes are not distinct). ValueError naming the
    element otherwise."""
    for index, row in enumerate(rows):
        if len(set(row)) != len(row):
            raise ValueError(f"{element} {index} repeats a Jacobian slot ({row}): its nodes must "
                             f"be distinct")
    return rows


@ti.data_oriented
class Assembly:
    """The view of one batch system that its force terms assemble into.

    `topology`: the shared `geometry.Topology`; `capacity`: instances (the batch axis of every
    field); `arena`: the `fields.FieldArena` the fields come from; `slot`: dict (i, j) -> the
    Jacobian block slot of nodes i, j that the terms couple (the `pattern_slot` of a
    `linsolve.EliminationPlan`: no fill-in, which only the factorisation writes); `integrator`: an
    `integrators` object; `state`: the fields `positions`, `previous`, `velocity_offset`
    ((capacity, N) 2-vectors), `fire_time`, `previous_fire_time` ((capacity, 8)) of a
    `state.BatchState`; `system`: the fields `rhs` ((capacity, N) 2-vectors) and `blocks`
    ((capacity, slots) 2×2) of a `linsolve.BlockSystem`; `primal_count`: in an engine with
    sensitivities, the field holding how many of its instances are simulated (the rest are
    their replicas, `engine.BatchEngine.replica`), else None."""

    def __init__(self, topology, capacity: int, arena, slot: dict, integrator, state, system,
                 primal_count=None):
        self.topology = topology
        self.capacity = capacity
        self.arena = arena
        self.slots = slot
        self.integrator = integrator
        self.positions = state.positions
        self.previous = state.previous
        self.velocity_offset = state.velocity_offset
        self.fire_time = state.fire_time
        self.previous_fire_time = state.previous_fire_time
        self.rhs = system.rhs
        self.blocks = system.blocks
        self.primal_count = primal_count
        self.replicated = primal_count is not None
        """Whether some instances are replicas of others (static: the terms' expansion of a
        replica about its instance is compiled only then)."""

    # ---------------------------------------------------------------- host side: tables
    def batch_field(self, dtype, shape) -> ti.Field:
        """A field of `shape` = (capacity, ...) (see `fields.FieldArena.batch_field`)."""
        return self.arena.batch_field(dtype, shape)

    def index(self, values) -> ti.Field:
        """An i32 field holding the integer table `values` (rows of node numbers or slots)."""
        return self.arena.index(values)

    def slot(self, i: int, j: int) -> int:
        """Slot of the Jacobian block (i, j) (KeyError when no term couples nodes i and j)."""
        return self.slots[i, j]

    def pair_slots(self, pairs) -> ti.Field:
        """(P, 4) Jacobian slots of the blocks (i,i), (i,j), (j,i), (j,j) of node pairs (i, j)."""
        return self.index(distinct_rows(
            [[self.slot(i, i), self.slot(i, j), self.slot(j, i), self.slot(j, j)]
             for i, j in pairs], "pair"))

    def triplet_slots(self, triplets) -> ti.Field:
        """(T, 9) Jacobian slots of the blocks (a, c) of each triplet's nodes, row-major."""
        return self.index(distinct_rows(
            [[self.slot(a, c) for a in nodes for c in nodes] for nodes in triplets], "triplet"))

    # ---------------------------------------------------------------- device side
    @ti.func
    def implicit_velocity(self, b, n, rate_gain):
        """Node n's velocity at the current iterate by the integrator's rate, m/s."""
        return rate_gain * (self.positions[b, n] - self.previous[b, n]) + self.velocity_offset[b, n]

    @ti.func
    def primal_instance(self, b):
        """b itself, or for a replica (only with `replicated`) the simulated instance it is a
        replica of. A replica's residual is differenced against its partner's at the
        instance's converged state, the pair's start states ±ε·Ṡ apart; a force that is not
        linear in the velocity (the drags, the jet) would put its own curvature into that
        difference, an error of order ε²·|Ṡ|²/|v|² per step that is large where the instance's
        velocity is near a zero (a kink) and builds up over a run. So such a term evaluates a
        replica's force and its velocity derivative at this instance's velocity (the replica's
        own coefficients) and adds the derivative times the replica's velocity offset: its
        first-order Taylor expansion about the instance, linear in the offset, whose pair
        difference is the derivative exactly (for coefficients that the force is linear in)."""
        primal = b
        if ti.static(self.replicated):
            # replica(b, j, sign) = count·(1 + 2j + sign) + b; a simulated b < count
            primal = b % self.primal_count[None]
        return primal

    @ti.func
    def rate_offset(self, value, previous, h, ratio, use_history):
        """The integrator's offset of the rate of a quantity whose value at the step's start is
        `value` and one step earlier `previous` (its rate is rate_gain·(now − value) + offset)."""
        return self.integrator.rate_offset(value, previous, h, ratio, use_history)

    @ti.func
    def add_block(self, b, slot, value, jacobian):
        """Add the 2×2 `value` to Jacobian block `slot` of instance b when `jacobian` is set."""
        # load + store, not `+=` (an atomic in Taichi): one thread owns instance b
        if jacobian:
            self.blocks[b, slot] = self.blocks[b, slot] + value

    @ti.func
    def add_residual(self, b, n, value):
        """Add the 2-vector `value` (N/m) to node n's residual of instance b."""
        self.rhs[b, n] = self.rhs[b, n] + value

    @ti.func
    def add_blocks(self, b, slots: ti.template(), row, values: ti.template(), jacobian):
        """Add `values` (a list of 2×2 blocks) to the Jacobian blocks `slots[row, 0..]` of
        instance b (distinct slots) when `jacobian` is set: every block is loaded before any is
        stored, the same sums as one `add_block` each. Stores through table-read slots keep the
        compiler from moving a later load above an earlier store, so added one by one each block
        is a round trip to memory waiting for the last; loaded together, a GPU thread has them
        all in flight at once."""
        if jacobian:
            slot = [slots[row, k] for k in ti.static(range(len(values)))]
            old = [self.blocks[b, slot[k]] for k in ti.static(range(len(values)))]
            for k in ti.static(range(len(values))):
                self.blocks[b, slot[k]] = old[k] + values[k]

    @ti.func
    def scatter_edge(self, b, slots: ti.template(), e, i, j, gradient, hessian, jacobian):
        """Scatter a term that depends on e = x_j − x_i alone, with gradient (2,) and Hessian
        (2, 2) with respect to e (∂/∂x_i = −∂/∂e); `slots` from `pair_slots`, row e (its
        blocks and the two nodes' residuals each loaded together, `add_blocks`)."""
        residual_i, residual_j = self.rhs[b, i], self.rhs[b, j]
        self.rhs[b, i] = residual_i - gradient
        self.rhs[b, j] = residual_j + gradient
        self.add_blocks(b, slots, e, [hessian, -hessian, -hessian, hessian], jacobian)

    @ti.func
    def scatter_triplet(self, b, slots: ti.template(), t, i, j, k, g1, g2, h11, h12, h22, jacobian):
        """Scatter a term of the two edges e1 = x_j − x_i, e2 = x_k − x_j of triplet t (gradients
        g1, g2; Hessian blocks h11, h12, h22, h21 = h12ᵀ): node derivatives by the incidence of
        the edges; `slots` from `triplet_slots`, row t (its blocks and the three nodes'
        residuals each loaded together, `add_blocks`)."""
        residual_i, residual_j, residual_k = self.rhs[b, i], self.rhs[b, j], self.rhs[b, k]
        self.rhs[b, i] = residual_i - g1
        self.rhs[b, j] = (residual_j + g1) - g2
        self.rhs[b, k] = residual_k + g2
        h21 = h12.transpose()
        self.add_blocks(b, slots, t, [h11, h12 - h11, -h12, h21 - h11, h11 - h12 - h21 + h22,
                                      h12 - h22, -h21, h21 - h22, h22], jacobian)
