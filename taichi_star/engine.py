"""The batch engine: B robot instances advanced in lock-step by an implicit integrator and
Newton's method, one Taichi thread per instance.

One kernel launch advances every live instance by a chunk of steps; inside it each instance runs
its own Newton loop (so converged instances stop iterating and failed ones are frozen at once),
assembles its residual and Jacobian from the force terms of `physics.TERMS` (each through the
engine's `physics.assembly.Assembly`) into a fixed-pattern block-sparse store (`linsolve.BlockSystem`) and solves it by LU without pivoting. Terms that no
instance of the batch uses are not part of the engine at all (compiled out). An engine built
with `lanes` > 1 (on the CPU; `runtime.Runtime.engine_lanes` says when) advances groups of
that many instances per thread with fixed steps, their Newton iterations interleaved round by
round and their systems factored and solved together in the vector lanes (`advance_group`),
each instance's bits those of its own loop.

An engine built `sensitive` also carries each instance's tangents (`tangent_step`): the batch's
first `primal_count` instances are simulated, and behind them, for each of `tangent_count`
replica pairs j, instance b has two replicas built at its parameters moved by +ε_j and −ε_j
(`replica`; the host gives each parameter one pair, at ±ε). A replica is never solved: after each accepted step of b its state is set to
b's state ± ε_j times the state's derivative, which the implicit function theorem gives exactly
from b's Jacobian at the converged state (see `tangent_step`), its rigid motion corrected so
that it obeys the rigid-body equations, which the Jacobian's stiffness blocks hold only to their
rounding (`rigid_correction`). Any output is then a smooth function of the replicas' states,
and its derivative is the central difference of the pair. A pair that moves only the gain or
the delay of an actuator that b has not yet fired has b's residual, and a tangent exactly
zero: it waits, its assembly and solve skipped, until that actuator first fires
(`replica_waiting`, `tangent_moves`); the bits are those of the pair not waiting.
"""


from typing import Dict

import numpy as np
import taichi as ti

from .linsolve import (BlockSystem, EliminationPlan, LaneBlocks, minimum_degree_order,
                       plan_elimination)
from .model import BatchModel
from .params import JACOBIANS, SolverConfig
from .physics import coupled_node_pairs
from .fields import FieldArena, FieldStore
from .physics.assembly import KEEP_EXPANSION, Assembly
from .physics.base import connect_terms, load_field, numpy_to_field_type, pad_batch
from . import stepping
from .gait import N_ACTUATORS, Gait
from .state import (STATUS_NEWTON_FAILED, STATUS_NON_FINITE, STATUS_OK, STATUS_STEP_LIMIT,
                    BatchState)
from .timegrid import MAX_STEPS_PER_INSTANCE, step_counts

ALL_TERMS, EXTERNAL_TERMS, INTERNAL_TERMS = range(3)
"""Which terms `BatchEngine.assemble_forces` assembles (static)."""

SAME_AS_INSTANCE, LINEAR_IN_DIFFERENCE = 1, 2
"""Values of `BatchEngine.same_as_instance` for a replica that leaves a term out (0: it
assembles it): its coefficients of the term are its instance's, or they differ only in the
term's `linear_coefficients`, whose difference the tangent step adds (`replica_sameness`)."""

SOLVER_SETTINGS = {"dt": float, "newton_tol": float, "residual_limit": float,
                   "max_newton": ti.i32, "max_substep_halvings": ti.i32, "jacobian_mode": ti.i32,
                   "error_tol": float, "dt_min": float, "dt_max": float}
"""The solver settings the kernels read, with their field types (all SolverConfig attributes of
the same name but `jacobian_mode`: the position of SolverConfig.jacobian in JACOBIANS)."""

JACOBIAN_NEWTON, JACOBIAN_LAGGED = (JACOBIANS.index(mode) for mode in ("newton", "lagged"))
"""`jacobian_mode` of SolverConfig.jacobian "newton" and "lagged" (the host tests the two; the
chord's is the kernels' business alone)."""

LAGGED_KEEP_MAX_UPDATES = 2
"""The most updates a converged solve may take for the lagged Jacobian to keep its
factorisation for the next step. More say that the kept factorisation (or the step) no longer
suits: in a heating pulse an old factorisation's first update rarely converges, and starting
the next step with a fresh one saves the iterations it would waste (over a pulse of A1+A3,
B = 512: 2.55 updates a step against 3.39 when every converged solve keeps it, measured
before Newton stopped only on an update within newton_tol, 2026-12)."""
LAGGED_MAX_AGE = 100
"""Most solves that start with a kept factorisation of the lagged Jacobian before a step
refactors anyway. Steps that converge after one update never measure how well an old
factorisation still contracts (the chord's rule refactors on a contraction under 4×), and the
error left after that update is bounded by the update only while it contracts at least 2×; 100
fixed steps (0.1 s at the default dt) keep its age well inside the shape's changes (a heating
pulse lasts 0.163 s)."""

FACTORISATION_PREFIX = "factorisation."
"""The names of the kept factorisations' arrays in a saved state (`BatchEngine.save_state`)."""

LOCKSTEP_MINIMUM_BATCH = 64
"""Simulated instances from which the fixed-step kernel of an engine with lanes iterates its
groups in lockstep (`advance_group`). Below it each instance runs on its own: a group of
few instances pays for all its lanes' factorisations, and few groups leave cores idle."""

ATTEMPT_GOES_ON, STEP_CONVERGED, STEP_FAILED = range(3)
"""Where a fixed step stands after a solve (`BatchEngine.after_solve`)."""

LANE_IDLE, LANE_STARTS, LANE_ITERATES = range(3)
"""What a lane's instance does next in a group of the fixed-step kernel
(`BatchEngine.advance_group`): nothing more in this launch, start a solve, or go on with its
Newton iteration."""

FINITE_LIMIT = 1e30
"""Updates larger than this (m) are treated as non-finite: no physical step moves a node 1e30 m."""


def elimination_plan(topology, terms_used) -> EliminationPlan:
    """The symbolic LU of the Newton matrix of an engine of `topology` and `terms_used`
    (`model.BatchModel.terms_used`): their pattern, eliminated in the minimum-degree order of
    every term's pattern in its default configuration. A switch that couples more nodes (the
    jet's "spread") adds blocks under that order, not an order of its own: an instance's pivots,
    and so its bits, do not depend on whether another instance of its batch switched it on
    (with its own order, a spread engine factored 3,741 block updates at N = 193 against
    6,053 now, and its other instances moved by ~1e-13)."""
    order = minimum_degree_order(topology.n_nodes, coupled_node_pairs(topology))
    return plan_elimination(topology.n_nodes, coupled_node_pairs(topology, terms_used),
                            order=order)


def replica_rows(primal_count: int, batch_size: int):
    """(replicas, instances, partners): the rows of the replicas of a batch of `primal_count`
    instances followed by their replicas (`BatchEngine.replica`: pair j's +ε replicas, then its
    −ε replicas), each one's simulated instance, and the other replica of each one's pair as an
    index into `replicas`."""
    replicas = np.arange(primal_count, batch_size)
    count = max(primal_count, 1)
    instances = replicas % count
    return replicas, instances, (((replicas - count) // count) ^ 1) * count + instances


@ti.data_oriented
class BatchEngine:
    """Device model, state and solver for up to `capacity` instances of one topology and one
    set of terms (`model.engine_key`). Compiled once per process and reused: the per-instance
    coefficients and the solver settings are loaded by `load`, not baked into the kernels.
    `instances_per_block`: threads (instances) per GPU block (1 on the CPU: one instance per
    task); `loop_spread`: parallel-loop iterations per instance of the capacity (see
    `advance`); `even_spread` (the CPU): the simulated instances placed evenly over those
    iterations (`slot_instance`); `instance_minor`: the GPU layout of the per-instance fields
    (`fields.FieldArena`); `lanes`: instances per group of the fixed-step kernel on the CPU
    (0 or 1: one at a time; see `advance_group`)."""

    def __init__(self, model: BatchModel, capacity: int, integrator, instances_per_block: int = 1,
                 loop_spread: int = 1, instance_minor: bool = False, sensitive: bool = False,
                 even_spread: bool = False, lanes: int = 0):
        topology = model.topology
        self.sensitive = sensitive
        """Whether the kernels carry the tangents of replicas (module docstring; static)."""
        self.topology = topology
        self.capacity = capacity
        self.instances_per_block = instances_per_block
        self.loop_spread = loop_spread
        self.even_spread = even_spread
        self.n_nodes = topology.n_nodes
        self.integrator = integrator
        self.plan = elimination_plan(topology, model.terms_used)
        self.arena = arena = FieldArena(instance_minor)
        self.system = BlockSystem(self.plan, capacity, arena)
        self.lanes = max(lanes, 1)
        """Instances per group of the fixed-step kernel (static): with more than one, a group's
        instances interleave their Newton solves round by round, factored and solved together
        in the CPU's vector lanes in lockstep (`advance_group`, `linsolve.LaneBlocks`)."""
        self.lane_system = LaneBlocks(self.system, -(-capacity // lanes), lanes, arena) \
            if lanes > 1 else None
        if lanes > 1:
            for name, dtype in (("newton_iterations", ti.i32), ("newton_converged", ti.i32),
                                ("newton_finite", ti.i32), ("newton_refactor", ti.i32),
                                ("newton_every_iteration", ti.i32),
                                ("newton_previous_update", float),
                                ("newton_largest_residual", float), ("lane_phase", ti.i32),
                                ("lane_last_step", ti.i32), ("lane_halvings", ti.i32),
                                ("lane_history", ti.i32), ("lane_substep", ti.i32)):
                setattr(self, name, arena.batch_field(dtype, capacity))
        """newton_*, lane_* (engines with lanes): each instance's Newton iteration and fixed-step
        attempt between the rounds of its group (`advance_group`); the one-instance kernel keeps
        them in registers."""
        self.state = BatchState(capacity, topology.n_nodes, arena)
        self.diagonal_slot = arena.index([self.plan.slot[n, n] for n in range(self.n_nodes)])
        self.mass = arena.batch_field(float, (capacity, self.n_nodes))
        self.inertia = arena.batch_field(float, (capacity, self.n_nodes))
        for name, dtype in SOLVER_SETTINGS.items():
            setattr(self, name, arena.field(dtype))
        self.primal_count = arena.field(ti.i32)
        """Instances simulated: all of the batch, or in a sensitive engine those before the
        replicas."""
        self.tangent_count = arena.field(ti.i32)
        """Directions whose tangents each simulated instance carries (0 unless sensitive)."""
        self.slot_stride = arena.field(ti.i32)
        """Parallel-loop iterations between two simulated instances (`slot_instance`)."""
        self.group_count = arena.field(ti.i32)
        """Groups of the fixed-step kernel (`group_member`): ⌈instances / lanes⌉ in lockstep,
        else one per instance."""
        self.group_stride = arena.field(ti.i32)
        """Parallel-loop iterations between two groups (`slot_group`)."""
        self.lockstep = arena.field(ti.i32)
        """1 where the groups iterate in lockstep (`advance_group`)."""
        self.step_limit = arena.field(ti.i32)
        """Most steps an adaptive instance takes (MAX_STEPS_PER_INSTANCE: the int32 counters
        never overflow); one that reaches it stops with status step_limit."""
        self.sliver_limit = arena.field(float)
        self.sliver_least = arena.field(float)
        self.sliver_most = arena.field(float)
        """`stepping.SLIVER_ROUNDINGS` roundings of the precision, and the shortest and longest
        bound of a sliver, s (`stepping.SLIVER_LEAST_OF_DT_MIN` and `SLIVER_MOST_OF_DT_MIN` of
        dt_min): an adaptive step that lands on a stop at most min(max(sliver_limit · max(|t|,
        1 s), sliver_least), sliver_most) after its start is a rounding's sliver
        (`stepping.is_sliver`), crossed by the clock alone."""
        self.kept_inertia_scale = arena.batch_field(float, capacity)
        self.kept_rate_gain = arena.batch_field(float, capacity)
        self.kept_age = arena.batch_field(ti.i32, capacity)
        """The factorisation blocks[b] holds (the lagged Jacobian reuses it across steps): the
        integrator weights its matrix was assembled with (inertia scale 1/s², rate gain 1/s;
        scale 0: none to reuse) and the solves that have started with it since."""
        self._factorisation_store = None
        """The kept factorisations' FieldStore (`factorisation_store`), once built."""
        self.assembly = Assembly(topology, capacity, arena, self.plan.pattern_slot, integrator,
                                 self.state, self.system,
                                 self.primal_count if sensitive else None)
        """What the terms see of this engine (they never hold the engine itself)."""
        term_classes = [cls for cls, _ in model.terms_used]
        self.terms = []
        for cls, configuration in model.terms_used:
            coefficients = model.coefficients[cls.name]
            shapes = {name: (values.shape[1:], numpy_to_field_type(values))
                      for name, values in coefficients.items()}
            self.terms.append(cls(self.assembly, configuration, shapes, term_classes))
        connect_terms(self.terms)
        self.same_as_instance = arena.batch_field(ti.i32, (capacity, len(self.terms))) \
            if sensitive else None
        """Per replica and term: SAME_AS_INSTANCE where the term does not read the step's
        start or pairs linearly (`Term.pairs_linearly`), no term that does read it reshapes it
        for the replica or its instance (`Term.start_reshapers`, `Term.reshaping`), and its
        coefficients are those of the replica's instance (the same whatever other instances
        the batch holds); LINEAR_IN_DIFFERENCE where they differ only in the term's
        `linear_coefficients` and no term reshapes it for either. `assemble` then leaves it
        out of both replicas of the pair: its residual at the instance's positions is the
        instance's for both, or the tangent step adds the pair's difference itself
        (`pair_difference`; 0 for the simulated instances, which assemble every term)."""
        self.waiting_actuator = arena.batch_field(ti.i32, capacity) if sensitive else None
        """Per replica: the index k of the actuator A(k+1) whose first firing its direction
        waits for, or −1 (`replica_waiting`); −1 for the simulated instances."""
        if sensitive:
            external_pairs = {frozenset(pair) for pair in coupled_node_pairs(
                model.topology, [term for term in model.terms_used if not term[0].internal])}
            external_slots = sorted([slot, i, j] for (i, j), slot in self.plan.slot.items()
                                    if i == j or frozenset((i, j)) in external_pairs)
            self.external_slot_nodes = arena.index(external_slots)
            """(slots, 3): the Jacobian slots that the inertia (the diagonal) and the terms
            that are not `internal` can fill, each with its block's row and column node, in
            slot order: what `rigid_projector_of` reads after the external terms' assembly,
            every other block being still zero then (609 of the paper robot's 1,675 slots)."""
            self.n_external_slots = len(external_slots)
            self.rigid_projector = arena.batch_field(float, (capacity, self.n_nodes),
                                                     matrix=(3, 2))
            """Per simulated instance and node m, the 3×2 map of a tangent step's x_m to its
            share of the net force and torque of J·x (`rigid_projector_of`)."""
        self.carrying = any(term.carries_state for term in self.terms)
        """Whether a term keeps state the positions do not determine (static: the kernels
        commit and back it up only then, `accept_step`)."""
        for term in self.terms:
            self.state.term_histories.update(
                {f"{term.name}.{name}": field for name, field in term.history_fields().items()})
        arena.finalize(fill_tables=False)
        model_fields = {name: getattr(self, name)
                        for name in ("mass", "inertia", "primal_count", "tangent_count",
                                     "slot_stride", "group_count", "group_stride", "lockstep",
                                     "step_limit", "sliver_limit", "sliver_least",
                                     "sliver_most", "kept_inertia_scale", *SOLVER_SETTINGS)}
        for term in self.terms:
            model_fields.update({f"{term.name}.{name}": field
                                 for name, field in term.coefficient_fields().items()})
        if sensitive:
            model_fields["same_as_instance"] = self.same_as_instance
            model_fields["waiting_actuator"] = self.waiting_actuator
        state_fields, zeroed = self.state.reset_fields()
        self.load_store = FieldStore(
            {**model_fields, **{name: field for name, (field, _) in arena.tables().items()},
             **{f"state.{name}": field for name, field in state_fields.items()}},
            zeroed=[f"state.{name}" for name in zeroed])
        """What `load` writes, in one kernel (each store is a kernel to compile, ~0.4 s
        whatever its size): the batch's coefficients, the solver settings, the index tables
        and the state at rest."""

    # ---------------------------------------------------------------- host side
    def term(self, name: str):
        """The device object of a term of this engine by its name (KeyError if not used)."""
        for term in self.terms:
            if term.name == name:
                return term
        raise KeyError(name)

    def load(self, model: BatchModel, solver: SolverConfig, periodic_gaits: bool = True,
             tangents: int = 0):
        """Copy a batch (at most `capacity` instances) and the solver settings to the device and
        put every instance at rest in its rest shape, status ok (padding: inactive). With
        `periodic_gaits`, each instance fires its gait at t = 0 and every period after;
        otherwise nothing fires until commanded (`fire`). `tangents` (a sensitive engine only):
        the batch is B simulated instances followed by their 2·tangents·B replicas, in the
        order of `replica`."""
        if model.batch_size > self.capacity:
            raise ValueError(f"batch of {model.batch_size} exceeds the engine capacity {self.capacity}")
        if tangents and not self.sensitive:
            raise ValueError("tangents need an engine built sensitive")
        if model.batch_size % (1 + 2 * tangents):
            raise ValueError(f"a batch of {model.batch_size} is not B instances and their "
                             f"2·{tangents}·B replicas")
        capacity = self.capacity
        primal_count = model.batch_size // (1 + 2 * tangents)
        slots = capacity * self.loop_spread
        lockstep = self.lanes > 1 and solver.jacobian == "newton" \
            and primal_count >= LOCKSTEP_MINIMUM_BATCH
        groups = -(-primal_count // self.lanes) if lockstep else primal_count
        values = {"mass": pad_batch(model.mass, capacity),
                  "inertia": pad_batch(model.inertia, capacity),
                  "primal_count": primal_count,
                  "tangent_count": tangents,
                  "slot_stride": slots // max(primal_count, 1) if self.even_spread
                  else self.loop_spread,
                  "group_count": groups,
                  "group_stride": slots // max(groups, 1) if self.even_spread
                  else self.loop_spread,
                  "lockstep": int(lockstep),
                  "step_limit": MAX_STEPS_PER_INSTANCE,
                  "sliver_limit": stepping.SLIVER_ROUNDINGS * float(np.finfo(
                      np.float64 if solver.precision == "f64" else np.float32).eps),
                  "sliver_least": stepping.SLIVER_LEAST_OF_DT_MIN * solver.dt_min,
                  "sliver_most": stepping.SLIVER_MOST_OF_DT_MIN * solver.dt_min,
                  # nothing kept: the weights and age of a factorisation are set with it
                  "kept_inertia_scale": np.zeros(capacity),
                  **{name: getattr(solver, name) for name in SOLVER_SETTINGS
                     if name != "jacobian_mode"},
                  "jacobian_mode": JACOBIANS.index(solver.jacobian)}
        for term in self.terms:
            coefficients = model.coefficients[term.name]
            values.update({f"{term.name}.{name}": pad_batch(coefficients[name], capacity)
                           for name in term.coefficient_names})
        if self.sensitive:
            values["same_as_instance"] = self.replica_sameness(model, primal_count)
            values["waiting_actuator"] = self.replica_waiting(model, primal_count)
        state = self.state.initial_values(pad_batch(model.rest_positions, capacity),
                                          model.batch_size)
        if periodic_gaits:
            masks = pad_batch(np.stack([Gait.parse(p.gait).mask for p in model.params]), capacity)
            periods = pad_batch(np.array([p.period for p in model.params]), capacity)
            self.state.schedule.periodic_values(state, masks, periods,
                                                step_counts(periods, solver.dt))
        state["step_size"][:] = solver.dt
        tables = {name: table for name, (_, table) in self.arena.tables().items()}
        self.load_store.write({**values, **tables,
                               **{f"state.{name}": array for name, array in state.items()}})

    def replica_sameness(self, model: BatchModel, primal_count: int) -> np.ndarray:
        """(capacity, terms) values of `same_as_instance` for a batch of `primal_count`
        instances followed by their replicas; the two replicas of a pair always alike (a term
        left out of one replica's residual and not the other's would put its whole residual
        into their difference: a damping time at 0 reshapes the +ε replica and not the −ε
        one), LINEAR_IN_DIFFERENCE for both where either is (the difference of coefficients
        alike is 0)."""
        same = np.zeros((self.capacity, len(self.terms)), dtype=np.int32)
        replicas, instances, partner_rows = replica_rows(primal_count, model.batch_size)

        def unreshaped(reshapers):
            free = np.ones(len(replicas), dtype=bool)
            for reshaper in reshapers:
                reshaped = reshaper.reshaping(model.coefficients[reshaper.name])
                if reshaped is None:
                    free[:] = False
                else:
                    free &= ~reshaped[replicas] & ~reshaped[instances]
            return free

        for k, term in enumerate(self.terms):
            if term.reads_step_start and not term.pairs_linearly:
                continue
            others_equal = np.ones(len(replicas), dtype=bool)
            linear_equal = np.ones(len(replicas), dtype=bool)
            for name in term.coefficient_names:
                values = model.coefficients[term.name][name]
                agree = (values[replicas] == values[instances]).reshape(len(replicas), -1).all(1)
                if name in term.linear_coefficients:
                    linear_equal &= agree
                else:
                    others_equal &= agree
            value = np.where(others_equal & linear_equal & unreshaped(term.start_reshapers),
                             SAME_AS_INSTANCE,
                             np.where(others_equal & unreshaped(term.reshapers),
                                      LINEAR_IN_DIFFERENCE, 0))
            partner = value[partner_rows]
            same[replicas, k] = np.where((value > 0) & (partner > 0),
                                         np.maximum(value, partner), 0)
        return same

    def replica_waiting(self, model: BatchModel, primal_count: int) -> np.ndarray:
        """(capacity,) values of `waiting_actuator` for a batch of `primal_count` instances
        followed by their replicas: k where a replica's rest shape, masses and coefficients
        are its instance's but for column k of the terms' `Term.fired_columns` (and its pair's
        the same: a gain or a delay of A(k+1)), else −1. Such a pair's residual is its
        instance's until actuator k first fires (the term reads that column only then), so
        from rest, with the instance, the pair stays on it: its tangent is exactly zero."""
        waiting = np.full(self.capacity, -1, dtype=np.int32)
        replicas, instances, partner_rows = replica_rows(primal_count, model.batch_size)
        if not len(replicas):
            return waiting

        def differs(values: np.ndarray) -> np.ndarray:
            return (values[replicas] != values[instances]).reshape(len(replicas), -1).any(1)

        elsewhere = differs(model.rest_positions) | differs(model.mass) | differs(model.inertia)
        columns = np.zeros((len(replicas), N_ACTUATORS), dtype=bool)
        for term in self.terms:
            for name in term.coefficient_names:
                values = model.coefficients[term.name][name]
                if name in term.fired_columns:
                    columns |= values[replicas] != values[instances]
                else:
                    elsewhere |= differs(values)
        single = ~elsewhere & (columns.sum(axis=1) == 1)
        actuator = np.where(single, columns.argmax(axis=1), -1)
        waiting[replicas] = np.where(actuator == actuator[partner_rows], actuator, -1)
        return waiting

    # ---------------------------------------------------------------- assembly
    @ti.func
    def implicit_velocity(self, b, n, rate_gain):
        """Node n's velocity at the current iterate by the integrator's rate, m/s."""
        return self.assembly.implicit_velocity(b, n, rate_gain)

    @ti.func
    def assemble(self, b, inertia_scale, rate_gain, jacobian):
        """Residual r = scale·M·((q − q_k) − d) + ∇E − F into rhs[b] and, if `jacobian`, its
        Jacobian into blocks[b], at the current iterate q = positions[b]: the integrator's
        inertia (with added mass), then every term in registry order."""
        self.assemble_forces(b, inertia_scale, rate_gain, jacobian, ALL_TERMS)

    @ti.func
    def assemble_forces(self, b, inertia_scale, rate_gain, jacobian, terms: ti.template()):
        """`assemble` (`terms` = ALL_TERMS); with EXTERNAL_TERMS the inertia and the terms that
        are not `internal` alone (what the rigid-body equations of instance b see: the internal
        forces' net force and torque vanish); with INTERNAL_TERMS the internal terms alone,
        added to what rhs[b] and blocks[b] hold. EXTERNAL_TERMS then INTERNAL_TERMS assemble
        the system of ALL_TERMS, its sums in another order."""
        if ti.static(terms != INTERNAL_TERMS):
            identity = ti.Matrix.identity(float, 2)
            self.system.clear(b, jacobian)
            if jacobian:
                # the blocks no longer hold a factorisation until `factor`
                self.kept_inertia_scale[b] = 0.0
            for n in range(self.n_nodes):
                scaled_mass = inertia_scale * self.inertia[b, n]
                self.assembly.add_residual(b, n, scaled_mass * (
                    (self.state.positions[b, n] - self.state.previous[b, n]) - self.state.inertia_offset[b, n]))
                self.assembly.add_block(b, self.diagonal_slot[n], scaled_mass * identity, jacobian)
        for k, term in ti.static(enumerate(self.terms)):
            if ti.static(terms == ALL_TERMS or (terms == INTERNAL_TERMS) == term.internal):
                if ti.static(self.sensitive and (not term.reads_step_start
                                                 or term.pairs_linearly)):
                    if self.same_as_instance[b, k] == 0:
                        term.assemble(b, rate_gain, jacobian)
                else:
                    term.assemble(b, rate_gain, jacobian)

    # ---------------------------------------------------------------- time stepping
    @ti.func
    def prepare_step(self, b, start_time, end_time, h, ratio, use_history, extrapolate):
        """Start a step of size h from the current state q_k, v_k: the terms' histories, the
        integrator's offsets, `previous` = q_k, and Newton's start (the integrator's
        `predictor`; `extrapolate`: from the parabola of adaptive steps). Returns the
        integrator's (inertia scale, rate gain)."""
        inertia_scale, rate_gain = self.integrator.weights(h, ratio, use_history)
        for term in ti.static(self.terms):
            term.begin_step(b, start_time, end_time, h, ratio, rate_gain, use_history)
        back = self.state.previous_step_size[b]
        for n in range(self.n_nodes):
            position = self.state.positions[b, n]
            velocity = self.state.velocities[b, n]
            self.state.inertia_offset[b, n] = self.integrator.inertia_offset(
                position, self.state.previous[b, n], velocity, self.state.previous_velocities[b, n],
                h, ratio, use_history)
            self.state.velocity_offset[b, n] = self.integrator.rate_offset(
                position, self.state.previous[b, n], h, ratio, use_history)
            predictor = self.integrator.predictor(
                position, self.state.previous[b, n], velocity, self.state.previous_velocities[b, n],
                h, back, use_history, extrapolate)
            self.state.previous[b, n] = position
            self.state.previous_velocities[b, n] = velocity
            self.state.positions[b, n] = predictor
        return inertia_scale, rate_gain

    @ti.func
    def solve_step(self, b, start_time, end_time, h, ratio, use_history, extrapolate):
        """One implicit step of size h for instance b from start_time to end_time. Returns
        (converged, finite); on failure the positions are restored to the start of the step."""
        inertia_scale, rate_gain = self.prepare_step(b, start_time, end_time, h, ratio, use_history,
                                                     extrapolate)
        iterations, converged, finite, previous_update, every_iteration = 0, 0, 1, 0.0, 0
        refactor = self.first_refactor(b, inertia_scale, rate_gain)
        while self.newton_goes_on(iterations, converged, finite):
            largest_residual = self.assemble_newton(b, inertia_scale, rate_gain, refactor)
            if refactor:
                self.factor(b, inertia_scale, rate_gain)
            self.system.solve(b)
            iterations, converged, finite, refactor, previous_update, every_iteration = \
                self.newton_iteration(b, iterations, previous_update, largest_residual,
                                      every_iteration)
        return self.finish_newton(b, rate_gain, iterations, converged, finite)

    @ti.func
    def first_refactor(self, b, inertia_scale, rate_gain):
        """Whether instance b's solve with these integrator weights (`integrator.weights`)
        starts by assembling and factoring its Jacobian (1), or with the factorisation that
        blocks[b] holds (0): only the lagged Jacobian's, made with the same weights (so for the
        same step size and integrator formula) at most LAGGED_MAX_AGE solves ago."""
        refactor = 1
        if self.jacobian_mode[None] == JACOBIAN_LAGGED \
                and self.kept_inertia_scale[b] == inertia_scale \
                and self.kept_rate_gain[b] == rate_gain and self.kept_age[b] < LAGGED_MAX_AGE:
            refactor = 0
            self.kept_age[b] = self.kept_age[b] + 1
        return refactor

    @ti.func
    def factor(self, b, inertia_scale, rate_gain):
        """Factor instance b's assembled Jacobian, made with these integrator weights, in
        place (the factorisation the lagged Jacobian may reuse, `first_refactor`)."""
        self.system.factor(b)
        self.kept_inertia_scale[b] = inertia_scale
        self.kept_rate_gain[b] = rate_gain
        self.kept_age[b] = 0

    @ti.func
    def newton_goes_on(self, iterations, converged, finite):
        """Whether a Newton iteration that has made `iterations` updates goes on."""
        return iterations < self.max_newton[None] and converged == 0 and finite == 1

    @ti.func
    def assemble_newton(self, b, inertia_scale, rate_gain, jacobian):
        """Instance b's residual (and, if `jacobian`, its Jacobian, which the iteration then
        factors: counted in `factorisations`) at the current iterate; returns its largest
        component for the opt-in residual test (0 without it)."""
        self.assemble(b, inertia_scale, rate_gain, jacobian)
        if jacobian:
            self.state.factorisations[b] = self.state.factorisations[b] + 1
        largest_residual = 0.0
        if self.residual_limit[None] < FINITE_LIMIT:  # the residual test is opt-in
            for n in range(self.n_nodes):
                residual = self.system.rhs[b, n]
                largest_residual = ti.max(largest_residual, ti.abs(residual[0]),
                                          ti.abs(residual[1]))
        return largest_residual

    @ti.func
    def newton_iteration(self, b, iterations, previous_update, largest_residual,
                         every_iteration):
        """End instance b's Newton iteration after the solve: `newton_update`, and where a
        chord or lagged iteration (`every_iteration` 0) has failed, ran out of iterations or
        made a non-finite update, the solve starts again from the step's start q_k with a
        Jacobian factored every iteration (`every_iteration` 1, Newton's), its own max_newton
        iterations. A chord update that fails to contract is applied before the iteration
        refactors, and at a firing that can throw the iterate where no later update
        converges although Newton's from the step's start does (a damped A1+A3 robot's
        re-firing: the chord ran out of iterations, the step was redone in substeps, and the
        shape ended 5·10⁻⁴ m off Newton's); the retry costs only solves that failed anyway,
        so runs without such a failure keep their bits. Returns (iterations, converged,
        finite, refactor, this update's size, every_iteration)."""
        iterations, converged, finite, refactor, update_size = self.newton_update(
            b, iterations, previous_update, largest_residual, every_iteration)
        if self.jacobian_mode[None] != JACOBIAN_NEWTON and every_iteration == 0 \
                and converged == 0 and not self.newton_goes_on(iterations, converged, finite):
            self.count_solve(b, iterations)
            for n in range(self.n_nodes):
                self.state.positions[b, n] = self.state.previous[b, n]
            iterations, finite, refactor, update_size, every_iteration = 0, 1, 1, 0.0, 1
        return iterations, converged, finite, refactor, update_size, every_iteration

    @ti.func
    def newton_update(self, b, iterations, previous_update, largest_residual, every_iteration):
        """Apply the Newton update that rhs[b] holds (solved) to instance b's positions after
        `iterations` updates, the last of size `previous_update` (m). Returns (iterations,
        converged, finite, refactor: for the chord and lagged Jacobians, unless they factor
        `every_iteration`, whether the next iteration refactors, this update's size)."""
        finite = 1
        largest_update = 0.0
        for n in range(self.n_nodes):
            update = self.system.rhs[b, n]
            self.state.positions[b, n] = self.state.positions[b, n] - update
            largest_update = ti.max(largest_update, ti.abs(update[0]), ti.abs(update[1]))
            if not (ti.abs(update[0]) < FINITE_LIMIT and ti.abs(update[1]) < FINITE_LIMIT):
                finite = 0
        iterations += 1
        # converged when the update itself is within newton_tol: what is left after it is then
        # smaller (far smaller with Newton's quadratic convergence; below newton_tol with the
        # chord's and the lagged Jacobian's in every step measured). The contraction estimate
        # θ/(1 − θ)·|Δ_k| (θ = |Δ_k|/|Δ_{k−1}|) stopped steps whose error was up to 34
        # newton_tol, the chord's up to 11 and the lagged Jacobian's up to 131, also where one
        # factorisation made both updates (an audit, 2026-12: docs/reliability.md, "Newton's
        # stopping rule")
        converged = 0
        if finite == 1 and largest_update <= self.newton_tol[None] \
                and largest_residual <= self.residual_limit[None]:
            converged = 1
        # the chord and lagged Jacobians keep the factorisation while it contracts the update
        # at least 4× per iteration (then each kept iteration saves the Jacobian's assembly
        # and LU)
        refactor = 1
        if self.jacobian_mode[None] != JACOBIAN_NEWTON and every_iteration == 0 \
                and (iterations == 1 or largest_update < 0.25 * previous_update):
            refactor = 0
        return iterations, converged, finite, refactor, largest_update

    @ti.func
    def count_solve(self, b, iterations):
        """Count a Newton solve of instance b that made `iterations` updates."""
        self.state.newton_total[b] = self.state.newton_total[b] + iterations
        self.state.newton_solves[b] = self.state.newton_solves[b] + 1
        self.state.newton_max[b] = ti.max(self.state.newton_max[b], iterations)

    @ti.func
    def finish_newton(self, b, rate_gain, iterations, converged, finite):
        """Count instance b's finished Newton iteration and set its velocities (converged) or
        restore its positions to the step's start (failed). A failed solve's factorisation,
        or that of one of more than LAGGED_KEEP_MAX_UPDATES updates, is not reused. Returns
        (converged, finite)."""
        if converged == 0 or iterations > LAGGED_KEEP_MAX_UPDATES:
            self.kept_inertia_scale[b] = 0.0
        self.count_solve(b, iterations)
        for n in range(self.n_nodes):
            if converged == 1:
                self.state.velocities[b, n] = self.implicit_velocity(b, n, rate_gain)
            else:
                self.state.positions[b, n] = self.state.previous[b, n]
        return converged, finite

    @ti.func
    def advance_instance(self, b, step_number):
        """Advance instance b to step_number by the fixed-step policy (`begin_step`,
        `after_solve`, `finish_step`), its Newton solves one after the other (`solve_step`).
        One call site of `solve_step` keeps the kernel (and its compile time) small."""
        halvings, history, substep = self.begin_step(b, step_number)
        converged, finite, outcome = 0, 1, ATTEMPT_GOES_ON
        while outcome == ATTEMPT_GOES_ON:
            start, end, h, use_history = self.attempt_interval(step_number, halvings, substep,
                                                               history)
            converged, finite = self.solve_step(b, start, end, h, 1.0, use_history, 0)
            halvings, history, substep, outcome = self.after_solve(
                b, step_number, halvings, history, substep, converged)
        self.finish_step(b, step_number, halvings, converged, finite)

    @ti.func
    def begin_step(self, b, step_number):
        """Start instance b's fixed step to step_number: fire what is due in it and return the
        first attempt (halvings 0, BDF2's history if instance b has one, substep 0).

        The fixed-step policy, whatever runs the solves: the step with the integrator's history
        when it has one; if it fails, the same step without history (Newton from q_k + h·v_k,
        implicit Euler), then from the saved start state 2, 4, ... 2^max_substep_halvings
        substeps without history; if those fail too, the instance is frozen at the start state
        with its status and failure step. An attempt is (halvings, history, substep)."""
        dt = self.dt[None]
        self.state.schedule.fire_due(b, (step_number - 1) * dt, step_number * dt, step_number)
        return 0, self.state.history_valid[b], 0

    @ti.func
    def attempt_interval(self, step_number, halvings, substep, history):
        """(start time, end time, size h (s), use_history) of the solve that an attempt at step
        step_number makes next."""
        substeps = 1 << halvings
        h = self.dt[None] / substeps
        first = (step_number - 1) * substeps + substep
        use_history = halvings == 0 and history == 1
        return first * h, (first + 1) * h, h, use_history

    @ti.func
    def after_solve(self, b, step_number, halvings, history, substep, converged):
        """After instance b's solve of an attempt (`attempt_interval`) ended, `converged` or
        not (its positions restored then): accept a converged substep (tangents, carried
        state), or move to the next attempt (keeping or restoring the start state). Returns the
        attempt then and the outcome: ATTEMPT_GOES_ON (another solve), STEP_CONVERGED or
        STEP_FAILED (every attempt failed)."""
        start, end, h, use_history = self.attempt_interval(step_number, halvings, substep,
                                                           history)
        outcome = ATTEMPT_GOES_ON
        if converged == 1:
            if ti.static(self.sensitive):
                self.tangent_step(b, start, end, h, 1.0, use_history)
            self.accept_step(b, h, 1.0, use_history)
            substep += 1
            if substep == 1 << halvings:
                outcome = STEP_CONVERGED
        else:
            substep = 0
            if use_history:
                # the carried acceleration can be a poor start where the forcing jumps (a
                # firing): the whole step again from q_k + h·v_k before any substeps
                history = 0
            else:
                halvings += 1
            if halvings > self.max_substep_halvings[None]:
                outcome = STEP_FAILED
            # the start state (restored by the failed solve) is kept when the substeps begin,
            # and restored before each later attempt and when the step has failed after them
            if halvings > 1 or (halvings == 1 and outcome == ATTEMPT_GOES_ON):
                self.copy_backup(b, halvings == 1)
        return halvings, history, substep, outcome

    @ti.func
    def finish_step(self, b, step_number, halvings, converged, finite):
        """Instance b's fixed step to step_number is over, `converged` in its last attempt
        (`halvings`) or frozen at the start state (`finite`: whether its last solve stayed
        finite): its history, counters, time or failure."""
        dt = self.dt[None]
        self.state.history_valid[b] = 1 if converged == 1 and halvings == 0 else 0
        if halvings > 0:
            self.state.substep_retries[b] = self.state.substep_retries[b] + 1
        if converged == 1:
            self.state.steps_done[b] = step_number
            self.state.time[b] = step_number * dt
        else:
            self.state.status[b] = STATUS_NON_FINITE if finite == 0 else STATUS_NEWTON_FAILED
            self.state.failure_step[b] = step_number
            self.state.failure_time[b] = step_number * dt
        self.mirror_replicas(b)

    @ti.func
    def adaptive_instance(self, b, max_steps):
        """Advance instance b towards its stop_time (s) by steps of its own size, at most
        max_steps attempts. Each step ends exactly on the stop, on the next cycle start of its
        periodic gait or on a commanded firing time if it would pass them (the firing happens
        there: the step ending at the firing time sees K̄(0), and is at most dt long);
        a converged step is accepted when its local error estimate (m, the largest node's
        `Integrator.local_error`) is within error_tol, else redone from the start state with the
        step shrunk (by a further √2 when the redo loses BDF2's history); the next step grows
        or shrinks by 0.9·√(tol/error) within [0.2, 2] and [dt_min, dt_max] (`stepping`: where
        a step ends, how its size changes). A step that fails to converge is retried at a
        quarter of its size down to dt_min, then the instance fails. An instance whose step
        count has reached `step_limit`, or whose next step would not advance its time, stops
        with status step_limit."""
        attempts = 0
        tol = self.error_tol[None]
        first_step = self.dt[None]
        dt_min, dt_max = self.dt_min[None], self.dt_max[None]
        stop_time = self.state.stop_time[b]
        while self.state.status[b] == STATUS_OK and self.state.time[b] < stop_time and attempts < max_steps:
            attempts += 1
            start = self.state.time[b]
            proposed = ti.min(self.state.step_size[b], dt_max)
            # the next stop: stop_time, or the next firing (a cycle start of the periodic gait
            # or a command) before it
            target = stop_time
            firing = 0
            due = self.state.schedule.next_firing(b, start)
            if due >= 0.0 and due <= target:
                target = due
                firing = 1
            # with dt_min = dt_max every step is that long: a stop or firing on the dt grid
            # lies a few roundings of the time from where the steps' sum lands
            # (`stepping.HELD_STEP_SLACK`; in f32 the time's roundings, 64 of them, are larger)
            slack = 0.0
            if dt_min == dt_max:
                slack = ti.max(stepping.HELD_STEP_SLACK * dt_min,
                               stepping.roundings(self.sliver_limit[None], target))
            end = stepping.step_end(start, proposed, target, firing, first_step, slack)
            if self.state.steps_done[b] >= self.step_limit[None] or end <= start:
                # the counter is full, or the step is below the time's rounding: stop here
                self.state.status[b] = STATUS_STEP_LIMIT
                self.state.failure_time[b] = start
                break
            if end != target:
                firing = 0
            h = end - start
            self.state.schedule.fire_due(b, start, end, 0)
            if stepping.is_sliver(start, end, target, self.sliver_limit[None],
                                  self.sliver_least[None], self.sliver_most[None]):
                # a stop a rounding's width after the last (a record time k·interval an ulp
                # off a cycle start): solved, a step this short turns the velocities into
                # rounding noise; the positions would move by far less than Newton's tolerance
                self.state.time[b] = end
                continue
            use_history = self.state.history_valid[b]
            ratio = 1.0
            if use_history == 1:
                ratio = h / self.state.previous_step_size[b]
            converged, finite = self.solve_step(b, start, end, h, ratio, use_history, use_history)
            error = 0.0
            if converged == 1:
                for n in range(self.n_nodes):
                    error = ti.max(error, self.integrator.local_error(
                        self.state.positions[b, n], self.state.previous[b, n],
                        self.state.previous_velocities[b, n], h))
            if converged == 1 and stepping.accepts(error, tol, h, proposed, dt_min):
                if ti.static(self.sensitive):
                    self.tangent_step(b, start, end, h, ratio, use_history)
                self.accept_step(b, h, ratio, use_history)
                self.state.time[b] = end
                self.state.steps_done[b] = self.state.steps_done[b] + 1
                if error > tol:
                    self.state.steps_over_tolerance[b] = self.state.steps_over_tolerance[b] + 1
                self.state.previous_step_size[b] = h
                self.state.history_valid[b] = 1
                self.state.step_size[b] = stepping.accepted_size(h, proposed, error, tol, firing,
                                                                 dt_min, dt_max)
            else:
                self.state.rejected_steps[b] = self.state.rejected_steps[b] + 1
                self.state.history_valid[b] = 0
                if converged == 1:
                    for n in range(self.n_nodes):
                        self.state.positions[b, n] = self.state.previous[b, n]
                        self.state.velocities[b, n] = self.state.previous_velocities[b, n]
                    # the retry has no history: with BDF2 it is an implicit Euler step, whose
                    # estimate at a given size is about twice that of a BDF2 step (h²q'' against
                    # ½h²q''), so it shrinks by a further √2
                    if ti.static(self.integrator.order == 2) and use_history == 1:
                        error *= 2.0
                    self.state.step_size[b] = stepping.rejected_size(h, error, tol, dt_min)
                elif not stepping.at_smallest(h, proposed, dt_min):
                    self.state.step_size[b] = ti.max(dt_min, 0.25 * h)
                else:
                    self.state.status[b] = STATUS_NON_FINITE if finite == 0 else STATUS_NEWTON_FAILED
                    self.state.failure_time[b] = end
        self.mirror_replicas(b)

    @ti.kernel
    def advance_adaptive(self, max_steps: ti.i32):
        """Adaptive stepping: advance every live instance towards its stop_time (s), at most
        max_steps step attempts each in this launch (the host calls again until all are there)."""
        ti.loop_config(block_dim=self.instances_per_block)
        for slot in range(self.capacity * self.loop_spread):
            b = self.slot_instance(slot)
            if b >= 0:
                self.adaptive_instance(b, max_steps)

    def advance_adaptive_to(self, stop_times: np.ndarray, batch_size: int, max_steps: int = 200):
        """Advance the first batch_size instances to their stop times (s, (batch_size,)) by
        adaptive steps; returns when every live one is there."""
        stops = self.state.stop_time.to_numpy()
        stops[:batch_size] = stop_times
        load_field(self.state.stop_time, stops)
        # the stops as the device holds them: in f32 a time reaches float32(t), and float32(0.35)
        # < 0.35 kept a comparison with the f64 stop true forever (the run never ended)
        stored = self.state.stop_time.to_numpy()[:batch_size]
        while True:
            times = self.state.time.to_numpy()[:batch_size]
            live = self.state.status.to_numpy()[:batch_size] == STATUS_OK
            if not (live & (times < stored)).any():
                return
            self.advance_adaptive(max_steps)

    @ti.func
    def copy_backup(self, b, save):
        """Positions and velocities of instance b and its replicas (and what the terms carry,
        `physics.base.Term.copy_carried`) into the backup (`save` = 1) or back from it (0)."""
        self.copy_instance_backup(b, save)
        if ti.static(self.sensitive):
            for j in range(self.tangent_count[None]):
                for sign in ti.static(range(2)):
                    self.copy_instance_backup(self.replica(b, j, sign), save)

    @ti.func
    def accept_step(self, b, h, ratio, use_history):
        """Let the terms that carry state commit instance b's accepted step (of size h, ratio
        and history as solved) and its replicas' (moved by `tangent_step`); nothing is compiled
        for a batch without such a term."""
        if ti.static(self.carrying):
            _, rate_gain = self.integrator.weights(h, ratio, use_history)
            for term in ti.static(self.terms):
                term.accept_step(b, rate_gain)
            if ti.static(self.sensitive):
                for j in range(self.tangent_count[None]):
                    for sign in ti.static(range(2)):
                        for term in ti.static(self.terms):
                            term.accept_step(self.replica(b, j, sign), rate_gain)

    @ti.func
    def copy_instance_backup(self, b, save):
        """`copy_backup` for instance (or replica) b alone, without its replicas."""
        for term in ti.static(self.terms):
            term.copy_carried(b, save)
        for n in range(self.n_nodes):
            if save:
                self.state.backup_positions[b, n] = self.state.positions[b, n]
                self.state.backup_velocities[b, n] = self.state.velocities[b, n]
            else:
                self.state.positions[b, n] = self.state.backup_positions[b, n]
                self.state.velocities[b, n] = self.state.backup_velocities[b, n]

    # ---------------------------------------------------------------- tangents (sensitive engines)
    @ti.func
    def slot_instance(self, slot):
        """The simulated instance (not a replica, not padding) that iteration `slot` of a
        parallel loop over capacity·loop_spread advances, or −1 (an idle iteration). Taichi's
        CPU backend hands each thread a contiguous share of a loop's range, so the instances sit
        `slot_stride` iterations apart: evenly over the whole range on the CPU (a batch of 5 in
        the 64-instance engine, or the first third of a sensitive engine's batch, would
        otherwise all fall to one thread), contiguously on a GPU (whole warps of instances)."""
        return self.spread_index(slot, self.slot_stride[None], self.primal_count[None])

    @ti.func
    def spread_index(self, slot, stride, count):
        """The one of `count` things (instances, groups), placed `stride` iterations apart,
        that iteration `slot` of a parallel loop advances, or −1."""
        # 0 until the first `load` (the counts are 0 too): nothing advances, nothing divides by 0
        stride = ti.max(stride, 1)
        index = -1
        if slot % stride == 0 and slot // stride < count:
            index = slot // stride
        return index

    @ti.func
    def replica(self, b, j, sign):
        """The instance holding simulated instance b moved along direction j by +ε_j (sign 0)
        or −ε_j (sign 1)."""
        count = self.primal_count[None]
        return count + (2 * j + sign) * count + b

    @ti.func
    def tangent_step(self, b, start_time, end_time, h, ratio, use_history):
        """After instance b's step from start_time to end_time (size h, ratio and history as
        solved) converged to q* = positions[b], move each of its replica pairs along the exact
        tangent of the step. For direction j the replicas hold the step's start state S ± ε·Ṡ
        and the coefficients c ± ε·ċ. Each runs the step's preparation (the terms' histories,
        the integrator's offsets) from its own state and assembles its residual at q*: half
        their difference is ε·(∂r/∂S·Ṡ + ∂r/∂c·ċ) up to O(ε³). The implicit function theorem
        on r(q*) = 0 gives ε·q̇* = −J⁻¹ times it, J the Jacobian at q* (assembled and factored
        here, so a chord run gets the exact one too, and a lagged run's next step starts with
        it), whose rigid motion `rigid_correction` then makes obey the rigid-body equations
        (net force and torque, by `rigid_projector_of`, from the inertia's and the external
        terms' blocks and the internal terms' residual). The replicas' positions become
        q* ± ε·q̇* and their velocities follow by the integrator's rate, which is linear in the
        positions; their fire times are b's (a firing is an event, not a function of the
        parameters). Nothing on the device divides by ε."""
        inertia_scale, rate_gain = self.integrator.weights(h, ratio, use_history)
        centre, total_mass, moment = self.mass_centre(b)
        self.assemble_with_rigid_projector(b, inertia_scale, rate_gain, centre)
        self.factor(b, inertia_scale, rate_gain)
        for j in range(self.tangent_count[None]):
            plus, minus = self.replica(b, j, 0), self.replica(b, j, 1)
            moving = self.tangent_moves(b, plus)
            # a loop, not unrolled: the replicas' preparation and assembly, every term inlined,
            # are compiled once, not twice (the sensitive kernel's compile time)
            for sign in range(2):
                r = self.replica(b, j, sign)
                for m in range(N_ACTUATORS):
                    self.state.fire_time[r, m] = self.state.fire_time[b, m]
                    self.state.previous_fire_time[r, m] = self.state.previous_fire_time[b, m]
                self.prepare_step(r, start_time, end_time, h, ratio, use_history, 0)
                for n in range(self.n_nodes):
                    self.state.positions[r, n] = self.state.positions[b, n]
                if moving:
                    self.assemble(r, inertia_scale, rate_gain, 0)
            if moving:
                for n in range(self.n_nodes):
                    self.system.rhs[b, n] = 0.5 * (self.system.rhs[plus, n]
                                                   - self.system.rhs[minus, n])
                for k, term in ti.static(enumerate(self.terms)):
                    if ti.static(term.pairs_linearly or bool(term.linear_coefficients)):
                        same = self.same_as_instance[plus, k]
                        if same != 0:
                            term.pair_difference(b, plus, minus, rate_gain,
                                                 same == LINEAR_IN_DIFFERENCE)
                wanted_force, wanted_torque = self.rigid_parts(b, centre)
                self.system.solve(b)
                self.rigid_correction(b, centre, wanted_force, wanted_torque,
                                      inertia_scale * total_mass, inertia_scale * moment)
            for n in range(self.n_nodes):
                # a waiting pair's difference would be exactly zero, and so its solve
                shift = ti.Vector.zero(float, 2)
                if moving:
                    shift = self.system.rhs[b, n]
                self.state.positions[plus, n] = self.state.positions[b, n] - shift
                self.state.positions[minus, n] = self.state.positions[b, n] + shift
                self.state.velocities[plus, n] = self.implicit_velocity(plus, n, rate_gain)
                self.state.velocities[minus, n] = self.implicit_velocity(minus, n, rate_gain)

    @ti.func
    def tangent_moves(self, b, plus):
        """Whether the replica pair of instance b whose +ε replica is `plus` needs its tangent
        step: not while the actuator its direction waits for (`waiting_actuator`) has never
        fired for b (its fire time, copied to the pair each step, still NEVER; a firing sets
        it, due within the step or before, and only a reset to rest or the load of a saved
        state clears it, each putting back the replicas with b)."""
        actuator = self.waiting_actuator[plus]
        moving = True
        if actuator >= 0:
            moving = self.state.fire_time[b, actuator] >= 0.0
        return moving

    @ti.func
    def weighted_centre(self, b, weights: ti.template()):
        """(Σ w_n·q_n / Σ w_n (m), Σ w_n) of instance b's positions q, `weights` a
        (capacity, N) field (the nodes' masses, or with the added mass the inertia's)."""
        total = 0.0
        weighted = ti.Vector.zero(float, 2)
        for n in range(self.n_nodes):
            weighted += weights[b, n] * self.state.positions[b, n]
            total += weights[b, n]
        return weighted / total, total

    @ti.func
    def mass_centre(self, b):
        """(mass centre c (m), total mass (kg/m), moment of inertia about c (kg)) of instance
        b's positions, with the inertia's masses (added mass included)."""
        centre, total_mass = self.weighted_centre(b, self.inertia)
        moment = 0.0
        for n in range(self.n_nodes):
            arm = self.state.positions[b, n] - centre
            moment += self.inertia[b, n] * arm.dot(arm)
        return centre, total_mass, moment

    @ti.func
    def assemble_with_rigid_projector(self, b, inertia_scale, rate_gain, centre):
        """`assemble` instance b's residual and Jacobian in two parts, the inertia and the
        external terms, then the internal terms, building `rigid_projector[b]` (about the mass
        centre `centre`) from each part as it is complete."""
        self.assemble_forces(b, inertia_scale, rate_gain, KEEP_EXPANSION, EXTERNAL_TERMS)
        self.rigid_projector_of(b, centre, True)
        self.assemble_forces(b, inertia_scale, rate_gain, 1, INTERNAL_TERMS)
        self.rigid_projector_of(b, centre, False)

    @ti.func
    def rigid_projector_of(self, b, centre, external_pass: ti.template()):
        """Build `rigid_projector[b]` in two passes over instance b's assembled system
        (`assemble_with_rigid_projector`): `external_pass` (static) True after
        `assemble_forces(..., EXTERNAL_TERMS)` (the inertia and the external terms' residual r_e
        and Jacobian J_e), False after the internal terms are added (`INTERNAL_TERMS`: the whole
        residual r). Then for any x, Σ_m P_m·x_m =
        (Σ_n (J·x)_n, Σ_n (q_n − c) × (J·x)_n), the net force and torque about c of J·x,
        computed without the internal terms' Jacobian: their blocks' column sums vanish and
        Σ_n (q_n − c) × (J_i·x)_n = −Σ_m x_m × r_i,m for the internal residual r_i = r − r_e
        (both by the internal energy's invariance under rigid motions, `Term.internal`)."""
        if ti.static(external_pass):
            for m in range(self.n_nodes):
                self.rigid_projector[b, m] = ti.Matrix.zero(float, 3, 2)
            for entry in range(self.n_external_slots):
                slot, row, column = (self.external_slot_nodes[entry, 0],
                                     self.external_slot_nodes[entry, 1],
                                     self.external_slot_nodes[entry, 2])
                block = self.system.blocks[b, slot]
                arm = self.state.positions[b, row] - centre
                share = ti.Matrix.zero(float, 3, 2)
                for k in ti.static(range(2)):
                    share[0, k] = block[0, k]
                    share[1, k] = block[1, k]
                    share[2, k] = arm[0] * block[1, k] - arm[1] * block[0, k]
                self.rigid_projector[b, column] = self.rigid_projector[b, column] + share
        # x_m × r_i,m = x_0·r_1 − x_1·r_0, with r_i = r − r_e: r enters with sign +, r_e −
        sign = -1.0 if ti.static(external_pass) else 1.0
        for m in range(self.n_nodes):
            residual = self.system.rhs[b, m]
            share = ti.Matrix.zero(float, 3, 2)
            share[2, 0] = -sign * residual[1]
            share[2, 1] = sign * residual[0]
            self.rigid_projector[b, m] = self.rigid_projector[b, m] + share

    @ti.func
    def rigid_parts(self, b, centre):
        """Net force (2,) and torque about `centre` of instance b's right-hand side rhs[b]
        (N/m, N)."""
        force = ti.Vector.zero(float, 2)
        torque = 0.0
        for n in range(self.n_nodes):
            value = self.system.rhs[b, n]
            force += value
            torque += (self.state.positions[b, n] - centre).cross(value)
        return force, torque

    @ti.func
    def rigid_correction(self, b, centre, wanted_force, wanted_torque, mass, moment):
        """Correct the rigid motion of the tangent step x in rhs[b] (J·x = ρ solved, ρ's net
        force and torque about the mass centre `wanted_force`, `wanted_torque`) so that J·x has
        ρ's net force and torque as computed by `rigid_projector`, `mass` and `moment` being
        the inertia's share of J in the rigid motions (kg/(m·s²), kg/s²).

        Why: the internal terms' blocks of J are the stiffness, ~10⁶ times the inertia's
        M/h² here, and their column sums, zero in exact arithmetic, keep a rounding of ~10⁻¹⁶
        of it, which the solve turns into an error of x's rigid motion (the stiffness's null
        space, held by the inertia alone). In a glide the robot's shape, and with it those
        roundings, repeat from step to step, so the error does not average out: it builds up
        as a drift of the tangent's rigid-body velocity. The projector computes the rigid
        equations of J·x without those blocks; one correction with the inertia as their
        Jacobian (the external terms' share is ~h·c/M, 10⁻³ here) removes the defect."""
        force = -wanted_force
        torque = -wanted_torque
        for m in range(self.n_nodes):
            share = self.rigid_projector[b, m] @ self.system.rhs[b, m]
            force += ti.Vector([share[0], share[1]])
            torque += share[2]
        translation = force / mass
        rotation = torque / moment
        for n in range(self.n_nodes):
            arm = self.state.positions[b, n] - centre
            self.system.rhs[b, n] = self.system.rhs[b, n] - (
                translation + rotation * ti.Vector([-arm[1], arm[0]]))

    @ti.func
    def mirror_replicas(self, b):
        """Give b's replicas its time, step count, status and failure (a failed instance's
        tangents are void: its outputs are NaN from its failure on, `simulation
        .failure_times`, which reads the failing step)."""
        if ti.static(self.sensitive):
            for j in range(self.tangent_count[None]):
                for sign in ti.static(range(2)):
                    r = self.replica(b, j, sign)
                    self.state.time[r] = self.state.time[b]
                    self.state.steps_done[r] = self.state.steps_done[b]
                    self.state.status[r] = self.state.status[b]
                    self.state.failure_time[r] = self.state.failure_time[b]
                    self.state.failure_step[r] = self.state.failure_step[b]

    @ti.func
    def slot_group(self, slot):
        """The group (`group_member`) that iteration `slot` of the fixed-step kernel's loop
        advances, or −1: placed as `slot_instance` places instances."""
        return self.spread_index(slot, self.group_stride[None], self.group_count[None])

    @ti.func
    def group_member(self, g, lane):
        """The simulated instance in lane `lane` of group g, or −1: lane l of group g holds
        instance l·G + g (G = group_count), so that a batch's instances fill the groups'
        first lanes evenly."""
        b = lane * self.group_count[None] + g
        if b >= self.primal_count[None]:
            b = -1
        return b

    @ti.func
    def advance_group(self, g, n_steps):
        """Advance every live instance of group g by n_steps fixed steps (`begin_step`,
        `after_solve`, `finish_step`: the policy of `advance_instance`), their Newton solves
        interleaved: in each round every lane that starts a solve prepares it, every lane that
        iterates assembles its system, the systems are solved (in lockstep: factored and solved
        together in the vector lanes, `linsolve.LaneBlocks`, a lane without an iterating
        instance computed and its result dropped; else each on its own, its chord Jacobian
        refactored as it decides), and each iterating lane applies its update; a lane whose
        solve ends moves on by the policy, to its next attempt or its next step, at once, so
        that no lane waits for the others. The kernel thus holds the assembly once. Every
        instance gets the bits of its own `advance_instance`."""
        for lane in range(self.lanes):
            b = self.group_member(g, lane)
            if b >= 0:
                self.lane_phase[b] = LANE_IDLE
                if self.state.status[b] == STATUS_OK and n_steps > 0:
                    self.lane_last_step[b] = self.state.steps_done[b] + n_steps
                    self.begin_lane_step(b)
        members = self.group_members(g)
        running = self.group_runs(g)
        while running == 1:
            for lane in range(self.lanes):
                b = self.group_member(g, lane)
                if b >= 0:
                    if self.lane_phase[b] == LANE_STARTS:
                        self.start_lane_solve(b)
            for lane in range(self.lanes):
                b = self.group_member(g, lane)
                if self.lane_iterates(b):
                    inertia_scale, rate_gain = self.lane_weights(b)
                    self.newton_largest_residual[b] = self.assemble_newton(
                        b, inertia_scale, rate_gain, self.newton_refactor[b])
            if self.lockstep[None] == 1:
                self.lane_system.gather(g, members)
                self.lane_system.factor(g)
                self.lane_system.solve(g)
                self.lane_system.scatter_solution(g, members)
            else:
                for lane in range(self.lanes):
                    b = self.group_member(g, lane)
                    if self.lane_iterates(b):
                        if self.newton_refactor[b]:
                            inertia_scale, rate_gain = self.lane_weights(b)
                            self.factor(b, inertia_scale, rate_gain)
                        self.system.solve(b)
            for lane in range(self.lanes):
                b = self.group_member(g, lane)
                if self.lane_iterates(b):
                    iterations, converged, finite, refactor, largest_update, every_iteration = \
                        self.newton_iteration(b, self.newton_iterations[b],
                                              self.newton_previous_update[b],
                                              self.newton_largest_residual[b],
                                              self.newton_every_iteration[b])
                    self.newton_iterations[b] = iterations
                    self.newton_every_iteration[b] = every_iteration
                    self.newton_converged[b] = converged
                    self.newton_finite[b] = finite
                    self.newton_refactor[b] = refactor
                    self.newton_previous_update[b] = largest_update
                    if not self.newton_goes_on(iterations, converged, finite):
                        self.end_lane_solve(b)
            running = self.group_runs(g)

    @ti.func
    def group_members(self, g):
        """The instances whose systems group g's lanes hold in lockstep (`linsolve.LaneBlocks`
        `gather`, `scatter_solution`): a ti.Vector of `lanes`, an empty lane repeating the
        group's first instance (its solution is dropped)."""
        members = ti.Vector([0] * self.lanes)
        for lane in ti.static(range(self.lanes)):
            b = self.group_member(g, lane)
            members[lane] = ti.select(b >= 0, b, g)
        return members

    @ti.func
    def group_runs(self, g):
        """1 while an instance of group g has a solve to start or to iterate."""
        runs = 0
        for lane in range(self.lanes):
            b = self.group_member(g, lane)
            if b >= 0:
                if self.lane_phase[b] != LANE_IDLE:
                    runs = 1
        return runs

    @ti.func
    def begin_lane_step(self, b):
        """`begin_step` of instance b's next step; its first solve starts in the next round."""
        halvings, history, substep = self.begin_step(b, self.state.steps_done[b] + 1)
        self.lane_halvings[b] = halvings
        self.lane_history[b] = history
        self.lane_substep[b] = substep
        self.lane_phase[b] = LANE_STARTS

    @ti.func
    def lane_attempt(self, b):
        """(start time, end time, h, use_history) of instance b's current solve."""
        return self.attempt_interval(self.state.steps_done[b] + 1, self.lane_halvings[b],
                                     self.lane_substep[b], self.lane_history[b])

    @ti.func
    def lane_weights(self, b):
        """The integrator's (inertia scale, rate gain) of instance b's current solve."""
        _, _, h, use_history = self.lane_attempt(b)
        return self.integrator.weights(h, 1.0, use_history)

    @ti.func
    def start_lane_solve(self, b):
        """`prepare_step` of instance b's current solve, its Newton iteration at the start."""
        start, end, h, use_history = self.lane_attempt(b)
        inertia_scale, rate_gain = self.prepare_step(b, start, end, h, 1.0, use_history, 0)
        self.newton_iterations[b] = 0
        self.newton_converged[b] = 0
        self.newton_finite[b] = 1
        self.newton_refactor[b] = self.first_refactor(b, inertia_scale, rate_gain)
        self.newton_every_iteration[b] = 0
        self.newton_previous_update[b] = 0.0
        self.lane_phase[b] = LANE_ITERATES

    @ti.func
    def end_lane_solve(self, b):
        """Instance b's Newton iteration has stopped: `finish_newton`, then the policy's next
        move (`after_solve`): another solve, the next step, or nothing more in this launch."""
        _, rate_gain = self.lane_weights(b)
        converged, finite = self.finish_newton(b, rate_gain, self.newton_iterations[b],
                                               self.newton_converged[b], self.newton_finite[b])
        step_number = self.state.steps_done[b] + 1
        halvings, history, substep, outcome = self.after_solve(
            b, step_number, self.lane_halvings[b], self.lane_history[b], self.lane_substep[b],
            converged)
        self.lane_halvings[b] = halvings
        self.lane_history[b] = history
        self.lane_substep[b] = substep
        self.lane_phase[b] = LANE_STARTS
        if outcome != ATTEMPT_GOES_ON:
            self.finish_step(b, step_number, halvings, converged, finite)
            self.lane_phase[b] = LANE_IDLE
            if self.state.status[b] == STATUS_OK and \
                    self.state.steps_done[b] < self.lane_last_step[b]:
                self.begin_lane_step(b)

    @ti.func
    def lane_iterates(self, b):
        """Whether the instance b of a lane (−1: none) is in a Newton iteration."""
        iterates = 0
        if b >= 0:
            if self.lane_phase[b] == LANE_ITERATES:
                iterates = 1
        return iterates

    @ti.kernel
    def advance(self, n_steps: ti.i32):
        """Advance every live instance by n_steps steps (from its own step count) in one
        launch."""
        # one instance per task on the CPU (Taichi's default grain of 32 would run a small batch
        # on one thread); a full block of instances per GPU block. Taichi's CPU backend runs a
        # parallel loop of fewer than ~1,024 iterations on one thread, so on the CPU the
        # instances are spread over `loop_spread` times as many iterations (the others idle),
        # evenly (`slot_instance`).
        ti.loop_config(block_dim=self.instances_per_block)
        for slot in range(self.capacity * self.loop_spread):
            if ti.static(self.lanes > 1):
                g = self.slot_group(slot)
                if g >= 0:
                    self.advance_group(g, n_steps)
            else:
                b = self.slot_instance(slot)
                if b >= 0:
                    for _ in range(n_steps):
                        if self.state.status[b] == STATUS_OK:
                            self.advance_instance(b, self.state.steps_done[b] + 1)

    def compile_stepping(self, adaptive: bool):
        """Compile the stepping kernel of fixed (`advance`) or adaptive (`advance_adaptive`)
        steps, or load it from Taichi's offline cache, by a launch that takes no step (the
        state is unchanged); returns once it is done, so that a caller can time compilation
        apart from the run. About free once this process has compiled it."""
        if adaptive:
            self.advance_adaptive(0)
        else:
            self.advance(0)
        ti.sync()

    @ti.kernel
    def compute_centroids(self, centroids: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        """centroids[b] (B, 2) = the mass-weighted mean of instance b's node positions now, m;
        written straight into the host's array (a field in between would be one kernel more to
        compile, its `to_numpy`, for every engine)."""
        for b in range(centroids.shape[0]):
            centre = self.weighted_centre(b, self.mass)[0]
            centroids[b, 0] = ti.cast(centre[0], ti.f64)
            centroids[b, 1] = ti.cast(centre[1], ti.f64)

    def centroids_of(self, batch_size: int) -> np.ndarray:
        """(B, 2) centroids of the first batch_size instances now, m (f64)."""
        centroids = np.empty((batch_size, 2), dtype=np.float64)
        self.compute_centroids(centroids)
        return centroids

    def save_state(self, factorisations: bool = False) -> Dict[str, np.ndarray]:
        """A copy of the batch's state (`BatchState.save`); with `factorisations`, also the
        factorisations the lagged Jacobian keeps (every instance's LU blocks and the weights
        and age they were made with, names starting "factorisation."), so that a lagged run
        put back from it goes on bit for bit as if never interrupted."""
        saved = self.state.save()
        if factorisations:
            saved.update({f"{FACTORISATION_PREFIX}{name}": values
                          for name, values in self.factorisation_store().read().items()})
        return saved

    def restore_state(self, saved: Dict[str, np.ndarray], check=None):
        """Put back a state from `save_state` (`BatchState.restore`, bitwise), and the kept
        factorisations where it holds them. Where it does not, an instance of a lagged run
        that this changes refactors at its next step (the others keep theirs, so that putting
        back some instances leaves the rest as they would have been). Raises ValueError, nothing
        changed, for a state of another layout, or one that `check` (a callable of the state's
        fields, called after their layout and values are checked) refuses."""
        kept = {name[len(FACTORISATION_PREFIX):]: values for name, values in saved.items()
                if name.startswith(FACTORISATION_PREFIX)}
        state = {name: values for name, values in saved.items()
                 if not name.startswith(FACTORISATION_PREFIX)}
        store = self.factorisation_store() if kept else None
        if store is not None:
            # an f32 copy of the blocks loaded rounded, the state no longer the snapshot's
            store.check_saved(kept, FACTORISATION_PREFIX)
        changed = self.state.changed_instances(state) \
            if self.jacobian_mode[None] == JACOBIAN_LAGGED and store is None else None
        self.state.restore(state, check)
        if store is not None:
            store.write(kept)
        elif changed is not None and changed.any():
            scale = self.kept_inertia_scale.to_numpy()
            scale[changed] = 0.0
            load_field(self.kept_inertia_scale, scale)

    def factorisation_store(self) -> FieldStore:
        """The fields of the kept factorisations (`first_refactor`) as one store, built at its
        first use (a store is a kernel to compile, and only lagged runs that save need it)."""
        if self._factorisation_store is None:
            self._factorisation_store = FieldStore({
                "blocks": self.system.blocks, "inertia_scale": self.kept_inertia_scale,
                "rate_gain": self.kept_rate_gain, "age": self.kept_age})
        return self._factorisation_store
