"""The batch engine: B robot instances advanced in lock-step by implicit Euler + Newton
(paper Eq. 4, design §2.6), one Taichi thread per instance.

One kernel launch advances every live instance by a chunk of steps; inside it each instance runs
its own Newton loop (so converged instances stop iterating and failed ones are frozen at once),
assembles its Jacobian into a fixed-pattern block-sparse store (`linsolve.BlockSystem`) and solves
it by LU without pivoting. Terms that no instance of the batch uses are compiled out.
"""

import numpy as np
import taichi as ti
from taichi.lang.util import to_numpy_type

from .actuation import CurvatureProfile
from .gait import N_ACTUATORS
from .geometry import SPOKE
from .linsolve import BlockSystem, plan_elimination
from .model import BatchModel
from .params import SolverConfig
from .physics import elastic, fluid

STATUS_OK, STATUS_NEWTON_FAILED, STATUS_NON_FINITE, STATUS_INACTIVE = 0, 1, 2, 3
STATUS_NAMES = ("ok", "newton_failed", "non_finite", "inactive")
"""Per-instance status; "inactive" marks the padding of a batch up to the engine's capacity."""
CENTRE = 0
FINITE_LIMIT = 1e30
"""Updates larger than this (m) are treated as non-finite: no physical step moves a node 1e30 m."""
TERM_ROD_DRAG, TERM_CYLINDER_DRAG, TERM_JET, TERM_ACTUATION = 1, 2, 4, 8
"""Bits of the `terms` template argument: a term no instance uses is compiled out."""


def terms_used(model: BatchModel) -> int:
    """The `terms` bitmask of the force terms some instance of the batch uses."""
    return (TERM_ROD_DRAG * model.uses_rod_drag + TERM_CYLINDER_DRAG * model.uses_cylinder_drag
            + TERM_JET * model.uses_jet + TERM_ACTUATION * model.uses_actuation)


def coupled_node_pairs(topology):
    """Node pairs (i, j) whose 2×2 Jacobian block can be non-zero: edges, all pairs of a bending
    triplet, and the hub's row against the jet quads' nodes."""
    pairs = [tuple(edge) for edge in topology.edges]
    for i, j, k in topology.triplets:
        pairs += [(i, j), (j, k), (i, k)]
    for quad in topology.jet_quads:
        pairs += [(CENTRE, node) for node in quad]
    return pairs


def _field(dtype, shape, values=None):
    """A field of `shape`, filled with `values` cast to its type (float = the runtime precision)."""
    field = ti.field(dtype, shape=shape)
    if values is not None:
        _load(field, values)
    return field


def _load(field, values):
    field.from_numpy(np.ascontiguousarray(values, dtype=to_numpy_type(field.dtype)))


def _pad(values: np.ndarray, capacity: int) -> np.ndarray:
    """Pad the batch axis up to capacity by repeating instance 0 (padding is inactive)."""
    padding = np.repeat(values[:1], capacity - len(values), axis=0)
    return np.concatenate([values, padding]) if len(padding) else values


@ti.data_oriented
class BatchEngine:
    """Device state for up to `capacity` instances of one topology. Compiled once per process
    and reused: the per-instance coefficients (shapes of `model.BatchModel`, padded to capacity)
    and the solver settings are loaded by `load`, not baked into the kernels.
    `positions`, `velocities`: (capacity, N) 2-vectors, m and m/s."""

    def __init__(self, topology, capacity: int, instances_per_block: int = 1):
        self.capacity = capacity
        self.instances_per_block = instances_per_block
        self.n_nodes = topology.n_nodes
        self.n_edges = topology.n_edges
        self.n_triplets = topology.n_triplets
        self.plan = plan_elimination(topology.n_nodes, coupled_node_pairs(topology))
        self.system = BlockSystem(self.plan, capacity)
        slot = self.plan.slot
        edges, triplets = topology.edges, topology.triplets
        self.edges = _field(ti.i32, edges.shape, edges)
        self.edge_is_spoke = _field(ti.i32, len(edges), topology.edge_kind == SPOKE)
        self.edge_slot = _field(ti.i32, (len(edges), 4), np.array(
            [[slot[i, i], slot[i, j], slot[j, i], slot[j, j]] for i, j in edges]))
        self.triplets = _field(ti.i32, triplets.shape, triplets)
        self.triplet_slot = _field(ti.i32, (len(triplets), 9), np.array(
            [[slot[a, c] for a in nodes for c in nodes] for nodes in triplets]))
        self.triplet_actuator = _field(ti.i32, len(triplets), topology.triplet_actuator)
        self.joint_actuator = _field(ti.i32, len(triplets), topology.joint_actuator)
        self.jet_quads = _field(ti.i32, topology.jet_quads.shape, topology.jet_quads)
        self.jet_slot = _field(ti.i32, (N_ACTUATORS, 5), np.array(
            [[slot[CENTRE, CENTRE]] + [slot[CENTRE, n] for n in quad] for quad in topology.jet_quads]))
        self.diagonal_slot = _field(ti.i32, self.n_nodes,
                                    np.array([slot[n, n] for n in range(self.n_nodes)]))
        self.profile = _field(float, 9, CurvatureProfile().as_array())
        self.dt = _field(float, ())
        self.newton_tol = _field(float, ())
        self.max_newton = _field(ti.i32, ())
        self.max_substep_halvings = _field(ti.i32, ())
        self.chord = _field(ti.i32, ())

        per_edge, per_triplet, per_node = ((capacity, n) for n in (self.n_edges, self.n_triplets,
                                                                   self.n_nodes))
        self.rest_length = _field(float, per_edge)
        self.edge_stiffness = _field(float, per_edge)
        self.drag_parallel_coeff = _field(float, per_edge)
        self.drag_perpendicular_coeff = _field(float, per_edge)
        self.voronoi_length = _field(float, per_triplet)
        self.rest_curvature = _field(float, per_triplet)
        self.end_turning_length = _field(float, per_triplet)
        self.bend_stiffness = _field(float, per_triplet)
        self.mass = _field(float, per_node)
        self.inertia = _field(float, per_node)
        self.cylinder_drag_coeff = _field(float, capacity)
        self.jet_alpha = _field(float, capacity)
        self.fluid_density = _field(float, capacity)
        self.jet_always = _field(ti.i32, capacity)
        self.period = _field(float, capacity)
        self.gait_mask = _field(ti.i32, (capacity, N_ACTUATORS))

        self.positions = ti.Vector.field(2, float, shape=per_node)
        self.previous = ti.Vector.field(2, float, shape=per_node)
        self.velocities = ti.Vector.field(2, float, shape=per_node)
        self.previous_velocities = ti.Vector.field(2, float, shape=per_node)
        self.inertia_offset = ti.Vector.field(2, float, shape=per_node)
        self.velocity_offset = ti.Vector.field(2, float, shape=per_node)
        self.backup_positions = ti.Vector.field(2, float, shape=per_node)
        self.backup_velocities = ti.Vector.field(2, float, shape=per_node)
        self.previous_areas = _field(float, (capacity, N_ACTUATORS))
        self.area_rate_offset = _field(float, (capacity, N_ACTUATORS))
        self.history_valid = ti.field(ti.i32, shape=capacity)
        self.substep_retries = ti.field(ti.i32, shape=capacity)
        self.status = ti.field(ti.i32, shape=capacity)
        self.failure_step = ti.field(ti.i32, shape=capacity)
        self.newton_total = ti.field(ti.i64, shape=capacity)
        self.newton_max = ti.field(ti.i32, shape=capacity)
        self.steps_done = ti.field(ti.i32, shape=capacity)
        self.centroids = ti.Vector.field(2, float, shape=capacity)

    def load(self, model: BatchModel, solver: SolverConfig):
        """Copy a batch (at most `capacity` instances) and the solver settings to the device and
        put every instance at rest in its rest shape, status ok (padding: inactive)."""
        if model.batch_size > self.capacity:
            raise ValueError(f"batch of {model.batch_size} exceeds the engine capacity {self.capacity}")
        for name in ("rest_length", "edge_stiffness", "drag_parallel_coeff",
                     "drag_perpendicular_coeff", "voronoi_length", "rest_curvature", "end_turning_length",
                     "bend_stiffness", "mass", "inertia", "cylinder_drag_coeff", "jet_alpha",
                     "fluid_density", "jet_always", "period", "gait_mask"):
            _load(getattr(self, name), _pad(getattr(model, name), self.capacity))
        rest = _pad(model.rest_positions, self.capacity)
        self.positions.from_numpy(rest.astype(to_numpy_type(self.positions.dtype)))
        self.velocities.fill(0.0)
        status = np.full(self.capacity, STATUS_INACTIVE, dtype=np.int32)
        status[:model.batch_size] = STATUS_OK
        self.status.from_numpy(status)
        self.failure_step.fill(-1)
        self.newton_total.fill(0)
        self.newton_max.fill(0)
        self.steps_done.fill(0)
        self.history_valid.fill(0)
        self.substep_retries.fill(0)
        self.max_substep_halvings[None] = solver.max_substep_halvings
        self.chord[None] = int(solver.jacobian == "chord")
        self.dt[None] = solver.dt
        self.newton_tol[None] = solver.newton_tol
        self.max_newton[None] = solver.max_newton

    # ---------------------------------------------------------------- assembly
    @ti.func
    def natural_curvature_target(self, b, time):
        """K̄(τ) (Eq. 5) at τ = time mod T for instance b, 1/m."""
        tau = time - self.period[b] * ti.floor(time / self.period[b])
        c1, c2, c3, c4 = self.profile[0], self.profile[1], self.profile[2], self.profile[3]
        if tau >= self.profile[8]:
            c1, c2, c3, c4 = self.profile[4], self.profile[5], self.profile[6], self.profile[7]
        return c1 / (1.0 + ti.exp(-c2 * (tau - c3))) + c4

    @ti.func
    def add_block(self, b, slot, value, jacobian):
        # load + store, not `+=` (an atomic in Taichi): one thread owns instance b
        if jacobian:
            self.system.blocks[b, slot] = self.system.blocks[b, slot] + value

    @ti.func
    def add_edge_pair(self, b, e, i, j, gradient, hessian, jacobian):
        """Scatter a term that depends on e = x_j − x_i alone: ∂/∂x_i = −∂/∂e."""
        self.system.rhs[b, i] = self.system.rhs[b, i] - gradient
        self.system.rhs[b, j] = self.system.rhs[b, j] + gradient
        self.add_block(b, self.edge_slot[e, 0], hessian, jacobian)
        self.add_block(b, self.edge_slot[e, 1], -hessian, jacobian)
        self.add_block(b, self.edge_slot[e, 2], -hessian, jacobian)
        self.add_block(b, self.edge_slot[e, 3], hessian, jacobian)

    @ti.func
    def assemble(self, b, target_curvature, inertia_scale, velocity_gain, jacobian,
                 terms: ti.template()):
        """Residual r = scale·M·((q − q_k) − d) + ∇E − F_ext into rhs[b] and, if `jacobian`,
        its Jacobian scale·M + ∇²E − ∂F_ext/∂q into blocks[b], at the current iterate
        q = positions[b] (for implicit Euler, Eq. 4: scale·M·((q − q_k) − d) = M(Δq − h·v_k)/h²)."""
        self.system.clear(b, jacobian)
        identity = ti.Matrix.identity(float, 2)
        # inertia with added mass, Eqs. 3-4: the integrator's diagonal mass term
        for n in range(self.n_nodes):
            scaled_mass = inertia_scale * self.inertia[b, n]
            self.system.rhs[b, n] = self.system.rhs[b, n] + scaled_mass * (
                (self.positions[b, n] - self.previous[b, n]) - self.inertia_offset[b, n])
            self.add_block(b, self.diagonal_slot[n], scaled_mass * identity, jacobian)
        # stretching, §III-A: E_s = ½ E r0 ε² Δl̄ on every edge
        for e in range(self.n_edges):
            i, j = self.edges[e, 0], self.edges[e, 1]
            gradient, hessian = elastic.stretch_gradient_hessian(
                self.positions[b, j] - self.positions[b, i], self.rest_length[b, e],
                self.edge_stiffness[b, e])
            self.add_edge_pair(b, e, i, j, gradient, hessian, jacobian)
        # bending, §III-A: E_b = ½ (E r0³/12)(κ − κ⁰)² Δl, κ⁰ driven by Eq. 5 on actuated arcs
        for t in range(self.n_triplets):
            self.add_bending(b, t, target_curvature, jacobian, terms)
        # rod drag, Eq. 1, per non-spoke edge on the mean implicit velocity
        if ti.static(terms & TERM_ROD_DRAG):
            for e in range(self.n_edges):
                if self.edge_is_spoke[e] == 0:
                    self.add_rod_drag(b, e, velocity_gain, jacobian)
        # cylinder drag, F^c of §III-A, on the centre
        if ti.static(terms & TERM_CYLINDER_DRAG):
            velocity = self.implicit_velocity(b, CENTRE, velocity_gain)
            force, d_velocity = fluid.cylinder_drag(velocity, self.cylinder_drag_coeff[b])
            self.system.rhs[b, CENTRE] = self.system.rhs[b, CENTRE] - force
            self.add_block(b, self.diagonal_slot[CENTRE], -velocity_gain * d_velocity, jacobian)
        # jet, Eq. 2, every inter-limb space pushing on the centre
        if ti.static(terms & TERM_JET):
            for k in range(N_ACTUATORS):
                self.add_jet(b, k, velocity_gain, jacobian)

    @ti.func
    def add_bending(self, b, t, target_curvature, jacobian, terms: ti.template()):
        i, j, k = self.triplets[t, 0], self.triplets[t, 1], self.triplets[t, 2]
        natural = self.rest_curvature[b, t]
        if ti.static(terms & TERM_ACTUATION):
            actuator = self.triplet_actuator[t]
            if actuator >= 0:
                if self.gait_mask[b, actuator] != 0:
                    natural = target_curvature if natural >= 0.0 else -target_curvature
            clamped = self.joint_actuator[t]
            if clamped >= 0 and self.end_turning_length[b, t] != 0.0:
                if self.gait_mask[b, clamped] != 0:
                    # turn the joint's natural angle φ⁰ = 2 atan(κ⁰Δl/2) by the arc's half-edge
                    voronoi = self.voronoi_length[b, t]
                    angle = 2.0 * ti.atan2(natural * voronoi, 2.0) + self.end_turning_length[b, t] * (
                        target_curvature - self.natural_curvature_target(b, 0.0))
                    natural = 2.0 * ti.tan(0.5 * angle) / voronoi
        g1, g2, h11, h12, h22 = elastic.bend_gradient_hessian(
            self.positions[b, j] - self.positions[b, i], self.positions[b, k] - self.positions[b, j],
            self.voronoi_length[b, t], natural, self.bend_stiffness[b, t])
        # e1 = x_j − x_i, e2 = x_k − x_j: node derivatives by the incidence of the two edges
        self.system.rhs[b, i] = self.system.rhs[b, i] - g1
        self.system.rhs[b, j] = self.system.rhs[b, j] + g1 - g2
        self.system.rhs[b, k] = self.system.rhs[b, k] + g2
        h21 = h12.transpose()
        self.add_block(b, self.triplet_slot[t, 0], h11, jacobian)
        self.add_block(b, self.triplet_slot[t, 1], h12 - h11, jacobian)
        self.add_block(b, self.triplet_slot[t, 2], -h12, jacobian)
        self.add_block(b, self.triplet_slot[t, 3], h21 - h11, jacobian)
        self.add_block(b, self.triplet_slot[t, 4], h11 - h12 - h21 + h22, jacobian)
        self.add_block(b, self.triplet_slot[t, 5], h12 - h22, jacobian)
        self.add_block(b, self.triplet_slot[t, 6], -h21, jacobian)
        self.add_block(b, self.triplet_slot[t, 7], h21 - h22, jacobian)
        self.add_block(b, self.triplet_slot[t, 8], h22, jacobian)

    @ti.func
    def add_rod_drag(self, b, e, velocity_gain, jacobian):
        i, j = self.edges[e, 0], self.edges[e, 1]
        velocity = 0.5 * (self.implicit_velocity(b, i, velocity_gain)
                          + self.implicit_velocity(b, j, velocity_gain))
        force, d_velocity, d_edge = fluid.rod_drag(
            velocity, self.positions[b, j] - self.positions[b, i],
            self.drag_parallel_coeff[b, e], self.drag_perpendicular_coeff[b, e])
        # half of F on each node; v is the mean of both, e = x_j − x_i
        d_first = 0.5 * (0.5 * velocity_gain * d_velocity - d_edge)
        d_second = 0.5 * (0.5 * velocity_gain * d_velocity + d_edge)
        self.system.rhs[b, i] = self.system.rhs[b, i] - 0.5 * force
        self.system.rhs[b, j] = self.system.rhs[b, j] - 0.5 * force
        self.add_block(b, self.edge_slot[e, 0], -d_first, jacobian)
        self.add_block(b, self.edge_slot[e, 1], -d_second, jacobian)
        self.add_block(b, self.edge_slot[e, 2], -d_first, jacobian)
        self.add_block(b, self.edge_slot[e, 3], -d_second, jacobian)

    @ti.func
    def add_jet(self, b, k, velocity_gain, jacobian):
        n1, n2 = self.jet_quads[k, 0], self.jet_quads[k, 1]
        n3, n4 = self.jet_quads[k, 2], self.jet_quads[k, 3]
        force, d_centre, d1, d2, d3, d4 = fluid.jet(
            self.positions[b, CENTRE], self.positions[b, n1], self.positions[b, n2],
            self.positions[b, n3], self.positions[b, n4], self.previous_areas[b, k],
            velocity_gain, self.area_rate_offset[b, k], self.jet_alpha[b],
            self.fluid_density[b], self.jet_always[b])
        self.system.rhs[b, CENTRE] = self.system.rhs[b, CENTRE] - force
        self.add_block(b, self.jet_slot[k, 0], -d_centre, jacobian)
        self.add_block(b, self.jet_slot[k, 1], -d1, jacobian)
        self.add_block(b, self.jet_slot[k, 2], -d2, jacobian)
        self.add_block(b, self.jet_slot[k, 3], -d3, jacobian)
        self.add_block(b, self.jet_slot[k, 4], -d4, jacobian)

    # ---------------------------------------------------------------- time stepping
    @ti.func
    def prepare_step(self, b, h, second_order):
        """Set the integrator's terms for a step of size h from the current state q_k, v_k and
        save that state in `previous`. The inertia residual is scale·M·((q − q_k) − d) and the
        implicit velocity v = gain·(q − q_k) + w (the jet's Ṡ likewise), with small offsets d, w
        so that f32 keeps the digits of the motion.
        Implicit Euler (Eq. 4): scale 1/h², gain 1/h, d = h·v_k, w = 0.
        BDF2: scale 9/(4h²), gain 3/(2h), d = (q_k − q_{k−1})/3 + (2h/9)(4v_k − v_{k−1}),
        w = −(q_k − q_{k−1})/(2h). Returns (scale, gain)."""
        inertia_scale = 1.0 / (h * h)
        velocity_gain = 1.0 / h
        if second_order:
            inertia_scale = 9.0 / (4.0 * h * h)
            velocity_gain = 1.5 / h
        for k in range(N_ACTUATORS):
            area = self.quad_area(b, k)
            rate_offset = 0.0
            if second_order:
                rate_offset = -(area - self.previous_areas[b, k]) / (2.0 * h)
            self.area_rate_offset[b, k] = rate_offset
            self.previous_areas[b, k] = area
        for n in range(self.n_nodes):
            position = self.positions[b, n]
            velocity = self.velocities[b, n]
            inertia_offset = h * velocity
            velocity_offset = ti.Vector.zero(float, 2)
            if second_order:
                step_back = position - self.previous[b, n]
                inertia_offset = step_back / 3.0 + (2.0 * h / 9.0) * (
                    4.0 * velocity - self.previous_velocities[b, n])
                velocity_offset = -step_back / (2.0 * h)
            self.inertia_offset[b, n] = inertia_offset
            self.velocity_offset[b, n] = velocity_offset
            self.previous[b, n] = position
            self.previous_velocities[b, n] = velocity
            self.positions[b, n] = position + h * velocity
        return inertia_scale, velocity_gain

    @ti.func
    def quad_area(self, b, k):
        """Area S of inter-limb space k (jet quad k) at the current positions, m²."""
        return ti.abs(fluid.quad_signed_area(
            self.positions[b, self.jet_quads[k, 0]], self.positions[b, self.jet_quads[k, 1]],
            self.positions[b, self.jet_quads[k, 2]], self.positions[b, self.jet_quads[k, 3]]))

    @ti.func
    def implicit_velocity(self, b, n, velocity_gain):
        return velocity_gain * (self.positions[b, n] - self.previous[b, n]) + self.velocity_offset[b, n]

    @ti.func
    def solve_step(self, b, end_time, h, second_order, terms: ti.template()):
        """One implicit step of size h for instance b ending at end_time (natural curvature at
        t_{k+1}, predictor q_k + h·v_k). Returns (converged, finite); on failure the state is
        restored to the start of the step."""
        target_curvature = 0.0
        if ti.static(terms & TERM_ACTUATION):
            target_curvature = self.natural_curvature_target(b, end_time)
        inertia_scale, velocity_gain = self.prepare_step(b, h, second_order)
        iterations = 0
        converged = 0
        finite = 1
        refactor = 1
        previous_update = 0.0
        while iterations < self.max_newton[None] and converged == 0 and finite == 1:
            self.assemble(b, target_curvature, inertia_scale, velocity_gain, refactor, terms)
            if refactor:
                self.system.factor(b)
            self.system.solve(b)
            largest_update = 0.0
            for n in range(self.n_nodes):
                update = self.system.rhs[b, n]
                self.positions[b, n] = self.positions[b, n] - update
                largest_update = ti.max(largest_update, ti.abs(update[0]), ti.abs(update[1]))
                if not (ti.abs(update[0]) < FINITE_LIMIT and ti.abs(update[1]) < FINITE_LIMIT):
                    finite = 0
            iterations += 1
            if finite == 1 and largest_update <= self.newton_tol[None]:
                converged = 1
            # chord mode keeps the factorisation while it contracts the update at least 4×
            # per iteration (then each kept iteration saves the Jacobian's assembly and LU)
            refactor = 1
            if self.chord[None] == 1 and (iterations == 1 or largest_update < 0.25 * previous_update):
                refactor = 0
            previous_update = largest_update
        self.newton_total[b] = self.newton_total[b] + iterations
        self.newton_max[b] = ti.max(self.newton_max[b], iterations)
        for n in range(self.n_nodes):
            if converged == 1:
                self.velocities[b, n] = self.implicit_velocity(b, n, velocity_gain)
            else:
                self.positions[b, n] = self.previous[b, n]
        return converged, finite

    @ti.func
    def advance_instance(self, b, step_number, second_order, terms: ti.template()):
        """Advance instance b to step_number: one step (BDF2 once it has a history of equal
        steps, else implicit Euler); if it fails, redo it from the saved start state as 2, 4,
        ... 2^max_substep_halvings implicit Euler substeps; if those fail too, freeze the
        instance at the start state with its status and failure step. One call site of
        `solve_step` keeps the kernel (and its compile time) small."""
        dt = self.dt[None]
        converged, finite = 0, 1
        halvings = 0
        while converged == 0 and halvings <= self.max_substep_halvings[None]:
            if halvings == 1:
                # a failed solve_step has restored the start state: keep it for later attempts
                for n in range(self.n_nodes):
                    self.backup_positions[b, n] = self.positions[b, n]
                    self.backup_velocities[b, n] = self.velocities[b, n]
            elif halvings > 1:
                self.restore_backup(b)
            substeps = 1 << halvings
            h = dt / substeps
            use_bdf2 = second_order and halvings == 0 and self.history_valid[b] == 1
            converged = 1
            substep = 0
            while converged == 1 and substep < substeps:
                end_time = ((step_number - 1) * substeps + substep + 1) * h
                converged, finite = self.solve_step(b, end_time, h, use_bdf2, terms)
                substep += 1
            if converged == 0:
                halvings += 1
        self.history_valid[b] = 1 if converged == 1 and halvings == 0 else 0
        if halvings > 0:
            self.substep_retries[b] = self.substep_retries[b] + 1
        if converged == 1:
            self.steps_done[b] = step_number
        else:
            if halvings > 1:
                self.restore_backup(b)
            self.status[b] = STATUS_NON_FINITE if finite == 0 else STATUS_NEWTON_FAILED
            self.failure_step[b] = step_number

    @ti.func
    def restore_backup(self, b):
        for n in range(self.n_nodes):
            self.positions[b, n] = self.backup_positions[b, n]
            self.velocities[b, n] = self.backup_velocities[b, n]

    @ti.kernel
    def advance(self, first_step: ti.i32, n_steps: ti.i32, second_order: ti.template(),
                terms: ti.template()):
        """Advance every live instance from step first_step by n_steps steps in one launch;
        `terms` is the TERM_* bitmask of the force terms to compile in, `second_order` selects
        BDF2 over implicit Euler."""
        # one instance per task on the CPU (Taichi's default grain of 32 would run a small batch
        # on one thread); a full block of instances per GPU block
        ti.loop_config(block_dim=self.instances_per_block)
        for b in range(self.capacity):
            for s in range(n_steps):
                if self.status[b] == STATUS_OK:
                    self.advance_instance(b, first_step + s + 1, second_order, terms)

    @ti.kernel
    def compute_centroids(self):
        """centroids[b] = mass-weighted mean of the current node positions (design §3)."""
        for b in range(self.capacity):
            weighted = ti.Vector.zero(float, 2)
            total = 0.0
            for n in range(self.n_nodes):
                weighted += self.mass[b, n] * self.positions[b, n]
                total += self.mass[b, n]
            self.centroids[b] = weighted / total
