"""SIMD across instances: does grouping instances into vector lanes speed up the CPU's block LU
and the assembly?

    python -m studies simd [--presets paper,accurate] [--precisions f64,f32]
                           [--batch-sizes 64,512,4096] [--lanes 4,8] [--repeats 7]
                           [--matmul-size 1024] [--kernels factor_solve,bending,rod_drag]
                           [--out DIR] [--quick]

A micro-benchmark of the kernel that dominates a Newton iteration on the CPU: the numeric block
LU factorisation of the Newton matrix on its fixed elimination pattern, and the forward/backward
solve (the engine's `BlockSystem.factor` and `solve`), on each preset's real pattern
(`EngineProfile.elimination_plan`) and random diagonally dominant matrices, in three forms of one
Taichi kernel whose per-instance arithmetic is identical:

- `instance_major`: today's engine. One loop iteration per instance; the matrix blocks of an
  instance are contiguous, as `batch_field` lays them out on the CPU.
- `unrolled_scalar`: each loop iteration advances `lanes` consecutive instances, the lane loop
  unrolled at compile time (`ti.static`), on scalar fields stored instance-minor (the same
  scalar of consecutive instances adjacent), so LLVM's SLP vectoriser could pack the lanes.
- `lane_vector`: the same unrolled lanes, on fields whose element is a `ti.Vector` of `lanes`
  scalars, one per instance (instances grouped in blocks of `lanes`, "array of structures of
  arrays"): the lanes of one scalar are one element, at constant offsets from one address.
- `lane_vector_masked`: `lane_vector` with every store masked per lane, as an engine whose
  converged or frozen instances sit out the rest of their group's Newton iterations would need:
  each store writes `ti.select(active, new, old)` with the lane mask `active` read from a field
  (all lanes active here, so the results stay comparable; the cost of the select does not
  depend on the mask).

Every form is compiled with Taichi's optimised LLVM IR printed (`print_kernel_llvm_ir_optimized`),
and the IR of its factor-and-solve kernel is searched for packed floating-point instructions
(`<N x double>` / `<N x float>` arithmetic). Timings are interleaved: each repeat restores the
matrices (untimed) and times one factor-and-solve of the whole batch in every form in turn, so
load from other processes hits all forms alike; a form's time is its best over the repeats,
`speedup_vs_instance_major` the ratio of the bests and `speedup_median_of_rounds` the median over
the rounds of the ratio of the two forms' times in that round (the steadier figure on a loaded
machine). NumPy's matrix product of two n × n
matrices (`--matmul-size`, same precision) is timed in the same rounds as the machine's
reference rate.

The assembly (`--kernels bending,rod_drag`): the Jacobian's two heaviest terms, each written
once on components so that the same function runs on one instance's scalars (today's form) and
on a group's lane vectors, over a chain of the preset's node count (`LaneAssembly`), scattered
into the residual and the Newton matrix's blocks by the same additions in every form:
- `bending`: the bending term's gradient and Hessian (`bend_element`: the engine's closed
  form, on the turning angle's half tangent), a triplet on every three consecutive nodes
  (`bending_chain`; the robot's star has about as many triplets, but its own pattern); its
  state (`bending_state`): a bent rod with random node offsets, the actuator's range of natural
  curvatures; checked against central differences of a NumPy copy of the energy
  (`gradient_error`).
- `rod_drag`: the rod drag on every edge of the chain and its derivatives in the velocity and
  the edge (`rod_drag_element`: the engine's closed form), on the mean implicit velocity of the
  edge's nodes, as the engine's term assembles it; its state (`rod_drag_state`): the bent rod
  swimming at a few cm/s, the paper's drag coefficients; its Jacobian checked against central
  differences of a NumPy copy of the residual (`rod_drag_jacobian_error`).
Timed like the LU (interleaved rounds), checked for bitwise equality across forms.

Writes `simd.csv` (the LU): one row per preset, precision, batch size and form: n_nodes,
n_slots (2×2 blocks with fill-in), lanes, flops_per_instance (factor + solve), seconds
(best), us_per_instance,
gflops, matmul_gflops (NumPy, best in the same rounds), fraction_of_matmul,
speedup_vs_instance_major, speedup_median_of_rounds, packed_ops_in_ir (packed floating-point
arithmetic instructions in the kernel's optimised IR), vector_width_in_ir (widest packed type
found, lanes; 0: none), max_relative_error (the solution against `numpy.linalg.solve` on the
dense matrix of checked instances), bitwise_equal_to_instance_major (every instance's solution),
load_average_1min (before the row's timings). `simd_assembly.csv` (the assemblies): one
row per term (`term`: bending, rod_drag), preset, precision, batch size and form: n_nodes,
n_elements (triplets or edges), lanes, seconds, us_per_instance, the two speed-ups,
packed_ops_in_ir, vector_width_in_ir, derivative_relative_error (instance 0's gradient, for
bending, or Jacobian, for the rod drag, against central differences, relative to its largest
entry), bitwise_equal_to_instance_major (the residual and the Jacobian's blocks of every
instance), load_average_1min. Each CSV comes with its plot (`simd.png`, `simd_assembly.png`):
the grouped forms' speed-ups against the batch size, drawn from the CSV.

--quick: the paper pattern, B = 8 and 16, f64 and f32, lanes 4, two repeats, 256 × 256 matmul.
"""

import contextlib
import io
import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import taichi as ti

from taichi_star import PRESETS, EngineProfile, SolverConfig, StarParams
from taichi_star.profiling import matmul_gflops
from taichi_star.provenance import cpu_model
from taichi_star.runtime import PARALLEL_LOOP_MINIMUM, Runtime, check_host_memory

from . import cli, provenance

DESCRIPTION = ("SIMD across instances: the Newton matrix's block LU in today's layout against "
               "lane-grouped forms, with the LLVM IR checked for vector instructions.")
KERNELS = ("factor_solve", "bending", "rod_drag")
"""The kernels the study times: the block LU (simd.csv), the bending term's and the rod drag's
assemblies (simd_assembly.csv)."""
FORMS = ("instance_major", "unrolled_scalar", "lane_vector", "lane_vector_masked")
VECTOR_FORMS = ("lane_vector", "lane_vector_masked")
"""The forms whose field elements are ti.Vectors of lanes."""
PRECISIONS = ("f64", "f32")
MAX_MATMUL_SIZE = 8192
"""The largest --matmul-size: its three n × n f64 matrices take 1.5 GiB."""
MAX_LANES = 16
"""The most instances per loop iteration (--lanes): the most lanes an engine takes
(`Runtime.configure_lanes`, bench's --lanes); the kernels unroll every lane (`ti.static`), so
a wider group only lengthens their compilation."""
DISTINCT_MATRICES = 64
"""Random matrices generated per configuration, repeated over the batch (the timing does not
depend on the values; generating 4,096 matrices of the accurate pattern would take longer than
timing them)."""
CHECKED_INSTANCES = 3
"""Instances (first, middle, last) whose solution is checked against numpy.linalg.solve."""
PACKED_OP = re.compile(r"= (?:fadd|fsub|fmul|fdiv|fneg)\b[^<\n]*<(\d+) x (?:double|float)>")


def solve_flops(plan) -> int:
    """Floating-point operations of one forward and backward solve: each neighbour block is a
    2×2 matrix-vector product and subtraction (8) once forward and once backward, each pivot
    inverse a 2×2 product (6)."""
    return int(16 * len(plan.neighbour_node) + 6 * plan.n_nodes)


def random_system(plan, count: int, seed: int):
    """(blocks (count, n_slots, 4), rhs (count, n_nodes, 2)) float64: `count` random matrices on
    the plan's pattern (fill-in slots included), block diagonally dominant so that LU without
    pivoting is stable, and random right-hand sides. Components row-major: a00, a01, a10, a11."""
    rng = np.random.default_rng(seed)
    blocks = rng.standard_normal((count, plan.n_slots, 4))
    row_blocks = np.zeros(plan.n_nodes)
    for i, _ in plan.slot:
        row_blocks[i] += 1
    diagonal = np.array([plan.slot[node, node] for node in range(plan.n_nodes)])
    shift = 4.0 * row_blocks  # a row's off-diagonal entries are about N(0, 1): 2 per block
    blocks[:, diagonal, 0] += shift
    blocks[:, diagonal, 3] += shift
    return blocks, rng.standard_normal((count, plan.n_nodes, 2))


def dense_matrix(plan, blocks: np.ndarray) -> np.ndarray:
    """(2N, 2N) dense matrix of one instance's blocks (n_slots, 4)."""
    matrix = np.zeros((2 * plan.n_nodes, 2 * plan.n_nodes))
    for (i, j), slot in plan.slot.items():
        matrix[2 * i:2 * i + 2, 2 * j:2 * j + 2] = blocks[slot].reshape(2, 2)
    return matrix


class LaneFields:
    """Per-instance fields of `batch` instances in `form` (FORMS) with `lanes` instances per loop
    iteration (1 for instance_major), in the current Taichi precision, and the accessors that
    read and write a group's lanes as one ti.Vector; the fields live in one SNode tree of their
    own (`destroy` frees it)."""

    def __init__(self, batch: int, form: str, lanes: int):
        if batch % lanes:
            raise ValueError(f"batch: a multiple of lanes = {lanes}, got {batch}")
        self.batch, self.form, self.lanes = batch, form, lanes
        self.groups = batch // lanes
        self.active = ti.Vector.field(lanes, ti.i32)

    def accessors(self):
        """(get, put): `get(field, g, entry, component)` the lanes of group g as a ti.Vector of
        `lanes` scalars, `put(field, g, entry, component, value)` their store (masked per lane
        by `active` in the masked form)."""
        lanes, form, active = self.lanes, self.form, self.active

        @ti.func
        def get(field: ti.template(), g, entry, component):
            if ti.static(form in VECTOR_FORMS):
                return field[g, entry, component]
            else:
                return ti.Vector([field[g * lanes + lane, entry, component]
                                  for lane in ti.static(range(lanes))])

        @ti.func
        def put(field: ti.template(), g, entry, component, value):
            if ti.static(form == "lane_vector_masked"):
                field[g, entry, component] = ti.select(active[g] != 0, value,
                                                       field[g, entry, component])
            elif ti.static(form == "lane_vector"):
                field[g, entry, component] = value
            else:
                for lane in ti.static(range(lanes)):
                    field[g * lanes + lane, entry, component] = value[lane]

        return get, put

    def group_loop(self, body):
        """A kernel running `body(g)` for every group, one group per task, the groups spread
        over at least PARALLEL_LOOP_MINIMUM loop iterations as the engine spreads its
        instances: Taichi's CPU backend runs a shorter parallel loop on one thread, which would
        favour whichever form has more iterations."""
        groups = self.groups
        spread = max(1, -(-PARALLEL_LOOP_MINIMUM // groups))

        @ti.kernel
        def run():
            ti.loop_config(block_dim=1)
            for slot in range(groups * spread):
                if slot % spread == 0:
                    body(slot // spread)

        return run

    def _finish(self, builder):
        """Place the lane mask (all lanes active), then build the SNode tree of `builder`."""
        builder.dense(ti.i, self.groups).place(self.active)
        self.tree = builder.finalize()
        self.active.from_numpy(np.ones((self.groups, self.lanes), dtype=np.int32))

    def _field(self, builder, entries: int, components: int):
        """(batch, entries, components) scalars in this form's layout."""
        if self.form in VECTOR_FORMS:
            field = ti.Vector.field(self.lanes, float)
            builder.dense(ti.ijk, (self.groups, entries, components)).place(field)
        else:
            field = ti.field(float)
            if self.form == "instance_major":
                builder.dense(ti.ijk, (self.batch, entries, components)).place(field)
            else:
                builder.dense(ti.jk, (entries, components)).dense(ti.i, self.batch).place(field)
        return field

    def to_layout(self, values: np.ndarray) -> np.ndarray:
        """(batch, entries, components) values as the field's from_numpy takes them."""
        if self.form not in VECTOR_FORMS:
            return values.astype(self._dtype())
        grouped = values.reshape(self.groups, self.lanes, *values.shape[1:])
        return np.ascontiguousarray(np.moveaxis(grouped, 1, -1)).astype(self._dtype())

    def from_layout(self, values: np.ndarray) -> np.ndarray:
        if self.form not in VECTOR_FORMS:
            return values
        return np.moveaxis(values, -1, 1).reshape(self.batch, *values.shape[1:3])

    @staticmethod
    def _dtype():
        return np.float64 if ti.lang.impl.get_runtime().default_fp == ti.f64 else np.float32

    def destroy(self):
        self.tree.destroy()


class LaneSystem(LaneFields):
    """The block LU of `plan` (see `LaneFields` for the layout arguments)."""

    def __init__(self, plan, batch: int, form: str, lanes: int):
        super().__init__(batch, form, lanes)
        self.plan = plan
        builder = ti.FieldsBuilder()
        self.blocks, self.pristine_blocks = (self._field(builder, plan.n_slots, 4)
                                             for _ in range(2))
        self.rhs, self.pristine_rhs = (self._field(builder, plan.n_nodes, 2) for _ in range(2))
        tables = {name: np.ascontiguousarray(getattr(plan, name), dtype=np.int32)
                  for name in ("order", "pivot_slot", "neighbour_start", "neighbour_node",
                               "lower_slot", "upper_slot", "update_start", "update_slot")}
        self.tables = {}
        for name, values in tables.items():
            self.tables[name] = ti.field(ti.i32)
            builder.dense(ti.i, max(len(values), 1)).place(self.tables[name])
        self._finish(builder)
        for name, values in tables.items():
            self.tables[name].from_numpy(values if len(values) else np.zeros(1, np.int32))
        self.factor_solve, self.restore = self._kernels()

    def load(self, blocks: np.ndarray, rhs: np.ndarray):
        """Set the matrices (batch, n_slots, 4) and right-hand sides (batch, n_nodes, 2)."""
        self.pristine_blocks.from_numpy(self.to_layout(blocks))
        self.pristine_rhs.from_numpy(self.to_layout(rhs))

    def solution(self) -> np.ndarray:
        """(batch, n_nodes, 2) the right-hand sides after factor_solve: the solutions."""
        return self.from_layout(self.rhs.to_numpy())

    def _kernels(self):
        lanes, plan = self.lanes, self.plan
        blocks, rhs, pristine_blocks, pristine_rhs = (self.blocks, self.rhs, self.pristine_blocks,
                                                      self.pristine_rhs)
        t = self.tables
        n_nodes = plan.n_nodes
        get, put = self.accessors()

        # a block of a group is a 4 × lanes matrix: its components a00, a01, a10, a11 (rows)
        # for every lane (columns); Taichi unrolls all of it into scalar code

        @ti.func
        def row(block, component):
            return ti.Vector([block[component, lane] for lane in ti.static(range(lanes))])

        @ti.func
        def get_block(g, slot):
            return ti.Matrix.rows([get(blocks, g, slot, component)
                                   for component in ti.static(range(4))])

        @ti.func
        def put_block(g, slot, block):
            for component in ti.static(range(4)):
                put(blocks, g, slot, component, row(block, component))

        @ti.func
        def product(x, y):
            """2×2 block products of every lane, in the order of Taichi's `@` (the engine's)."""
            return ti.Matrix.rows([
                row(x, 0) * row(y, 0) + row(x, 1) * row(y, 2),
                row(x, 0) * row(y, 1) + row(x, 1) * row(y, 3),
                row(x, 2) * row(y, 0) + row(x, 3) * row(y, 2),
                row(x, 2) * row(y, 1) + row(x, 3) * row(y, 3)])

        @ti.func
        def invert(block):
            inverse_determinant = 1.0 / (row(block, 0) * row(block, 3)
                                         - row(block, 1) * row(block, 2))
            return ti.Matrix.rows([inverse_determinant * row(block, 3),
                                   -inverse_determinant * row(block, 1),
                                   -inverse_determinant * row(block, 2),
                                   inverse_determinant * row(block, 0)])

        @ti.func
        def factor(g):
            for p in range(n_nodes):
                inverse = invert(get_block(g, t["pivot_slot"][p]))
                put_block(g, t["pivot_slot"][p], inverse)
                start = t["neighbour_start"][p]
                count = t["neighbour_start"][p + 1] - start
                for a in range(count):
                    lower = t["lower_slot"][start + a]
                    put_block(g, lower, product(get_block(g, lower), inverse))
                update = t["update_start"][p]
                for a in range(count):
                    lower_block = get_block(g, t["lower_slot"][start + a])
                    for c in range(count):
                        target = t["update_slot"][update + a * count + c]
                        upper_block = get_block(g, t["upper_slot"][start + c])
                        put_block(g, target, get_block(g, target)
                                  - product(lower_block, upper_block))

        @ti.func
        def solve(g):
            for p in range(n_nodes):
                node = t["order"][p]
                x0, x1 = get(rhs, g, node, 0), get(rhs, g, node, 1)
                for a in range(t["neighbour_start"][p], t["neighbour_start"][p + 1]):
                    neighbour = t["neighbour_node"][a]
                    lower_block = get_block(g, t["lower_slot"][a])
                    r0 = get(rhs, g, neighbour, 0) - (row(lower_block, 0) * x0
                                                      + row(lower_block, 1) * x1)
                    r1 = get(rhs, g, neighbour, 1) - (row(lower_block, 2) * x0
                                                      + row(lower_block, 3) * x1)
                    put(rhs, g, neighbour, 0, r0)
                    put(rhs, g, neighbour, 1, r1)
            for reverse in range(n_nodes):
                p = n_nodes - 1 - reverse
                node = t["order"][p]
                v0, v1 = get(rhs, g, node, 0), get(rhs, g, node, 1)
                for a in range(t["neighbour_start"][p], t["neighbour_start"][p + 1]):
                    upper_block = get_block(g, t["upper_slot"][a])
                    neighbour = t["neighbour_node"][a]
                    y0, y1 = get(rhs, g, neighbour, 0), get(rhs, g, neighbour, 1)
                    v0 -= row(upper_block, 0) * y0 + row(upper_block, 1) * y1
                    v1 -= row(upper_block, 2) * y0 + row(upper_block, 3) * y1
                pivot = get_block(g, t["pivot_slot"][p])
                solved0 = row(pivot, 0) * v0 + row(pivot, 1) * v1
                solved1 = row(pivot, 2) * v0 + row(pivot, 3) * v1
                put(rhs, g, node, 0, solved0)
                put(rhs, g, node, 1, solved1)

        @ti.func
        def factor_solve(g):
            factor(g)
            solve(g)

        @ti.func
        def restore(g):
            for entry, component in ti.ndrange(plan.n_slots, 4):
                put(blocks, g, entry, component, get(pristine_blocks, g, entry, component))
            for entry, component in ti.ndrange(n_nodes, 2):
                put(rhs, g, entry, component, get(pristine_rhs, g, entry, component))

        return self.group_loop(factor_solve), self.group_loop(restore)


@ti.func
def bend_element(e1x, e1y, e2x, e2y, voronoi_length, natural_curvature, stiffness):
    """The bending energy's gradient and Hessian of one triplet in the engine's closed form
    (`E_b = ½·B·(κ − κ⁰)²·Δl`, κ = 2·tan(φ/2)/Δl, through the edges' polar angles), written on
    components so that every argument may be a scalar (one instance) or a ti.Vector of lanes
    (one scalar of each of `lanes` instances): the same operations in the same order either
    way. Edges e1 = x_j − x_i, e2 = x_k − x_j (m). Returns (g1x, g1y, g2x, g2y) and the
    Hessian's blocks H11 (xx, xy, yy), H22 (xx, xy, yy), H12 (xx, xy, yx, yy). A copy of the
    engine's `bend_gradient_hessian` on components, on purpose: the study stands alone (as its
    LU does), studies do not import the engine's physics, and the engine's form on 2-vectors
    does not carry lanes."""
    squared1 = e1x * e1x + e1y * e1y
    squared2 = e2x * e2x + e2y * e2y
    cross = e1x * e2y - e1y * e2x
    half_tangent = cross / (ti.sqrt(squared1) * ti.sqrt(squared2) + (e1x * e2x + e1y * e2y))
    curvature = 2.0 * half_tangent / voronoi_length
    dcurv = (1.0 + half_tangent * half_tangent) / voronoi_length
    d2curv = half_tangent * dcurv
    scale = stiffness * voronoi_length
    excess = curvature - natural_curvature
    energy_phi = scale * excess * dcurv
    energy_phi_phi = scale * (dcurv * dcurv + excess * d2curv)
    # the polar angles' gradients and Hessians
    a1x, a1y = -e1y / squared1, e1x / squared1
    a2x, a2y = -e2y / squared2, e2x / squared2
    q1 = squared1 * squared1
    q2 = squared2 * squared2
    b1xx, b1xy = 2.0 * e1x * e1y / q1, (e1y * e1y - e1x * e1x) / q1
    b2xx, b2xy = 2.0 * e2x * e2y / q2, (e2y * e2y - e2x * e2x) / q2
    gradients = (-energy_phi * a1x, -energy_phi * a1y, energy_phi * a2x, energy_phi * a2y)
    h11 = (energy_phi_phi * a1x * a1x - energy_phi * b1xx,
           energy_phi_phi * a1x * a1y - energy_phi * b1xy,
           energy_phi_phi * a1y * a1y + energy_phi * b1xx)
    h22 = (energy_phi_phi * a2x * a2x + energy_phi * b2xx,
           energy_phi_phi * a2x * a2y + energy_phi * b2xy,
           energy_phi_phi * a2y * a2y - energy_phi * b2xx)
    h12 = (-energy_phi_phi * a1x * a2x, -energy_phi_phi * a1x * a2y,
           -energy_phi_phi * a1y * a2x, -energy_phi_phi * a1y * a2y)
    return gradients, h11, h22, h12


BEND_COUPLING = ((-1.0, 0.0), (1.0, -1.0), (0.0, 1.0))
"""d(e1, e2)/d(node) of a triplet's nodes i, j, k (times the identity): node a's Hessian block
with node c is Σ_pq BEND_COUPLING[a][p]·BEND_COUPLING[c][q]·H_pq."""


def bending_chain(n_nodes: int) -> np.ndarray:
    """(T, 3) the triplets of a chain of n_nodes: one on every three consecutive nodes."""
    return np.stack([np.arange(n_nodes - 2) + offset for offset in range(3)], axis=1)


def chain_slots(n_nodes: int) -> dict:
    """The blocks of a chain's Newton matrix, slot[(a, c)] for |a − c| ≤ 2 (row-major): what a
    bending triplet on three consecutive nodes fills, and an edge's pair within it."""
    slot = {}
    for a in range(n_nodes):
        for c in range(max(0, a - 2), min(n_nodes, a + 3)):
            slot[a, c] = len(slot)
    return slot


class LaneAssembly(LaneFields):
    """A term's assembly over a chain of n_nodes, its residual into `residual` (n_nodes, 2) and
    its Jacobian into `blocks` (chain_slots, 4) (see `LaneFields` for the layout arguments):
    per element (`elements` (E, k) of its k nodes, `element_slots` (E, k²) of its node blocks
    in the order (nodes) × (nodes)) the subclass's element function, on scalars of one
    instance in the instance-major form and on lane vectors in the others, scattered by the
    same additions in the same order. A subclass names its per-node state fields
    (`node_fields`) and its per-element values (`element_columns`), and writes `_element`."""

    node_fields = ("positions",)
    element_columns = 0

    def __init__(self, n_nodes: int, batch: int, form: str, lanes: int, elements: np.ndarray):
        super().__init__(batch, form, lanes)
        self.n_nodes, self.elements = n_nodes, elements.astype(np.int32)
        self.n_elements, nodes_per_element = elements.shape
        self.slot = chain_slots(n_nodes)
        element_slots = np.array([[self.slot[a, c] for a in element for c in element]
                                  for element in elements], dtype=np.int32)
        builder = ti.FieldsBuilder()
        self.state = {name: self._field(builder, n_nodes, 2) for name in self.node_fields}
        self.element = self._field(builder, self.n_elements, self.element_columns)
        self.residual = self._field(builder, n_nodes, 2)
        self.blocks = self._field(builder, len(self.slot), 4)
        self.element_nodes = ti.field(ti.i32)
        self.element_slots = ti.field(ti.i32)
        builder.dense(ti.ij, (self.n_elements, nodes_per_element)).place(self.element_nodes)
        builder.dense(ti.ij, (self.n_elements, nodes_per_element ** 2)).place(self.element_slots)
        self._finish(builder)
        self.element_nodes.from_numpy(self.elements)
        self.element_slots.from_numpy(element_slots)
        self.assemble = self._kernel()

    def load(self, state: dict, element: np.ndarray):
        """Per-node state {name: (batch, n_nodes, 2)} (`node_fields`) and per element
        (batch, E, element_columns) its values."""
        for name, values in state.items():
            self.state[name].from_numpy(self.to_layout(values))
        self.element.from_numpy(self.to_layout(element))

    def assembled_residual(self) -> np.ndarray:
        """(batch, n_nodes, 2) the assembled residual."""
        return self.from_layout(self.residual.to_numpy())

    def jacobian_blocks(self) -> np.ndarray:
        """(batch, n_slots, 4) the assembled Jacobian's blocks (xx, xy, yx, yy)."""
        return self.from_layout(self.blocks.to_numpy())

    def _kernel(self):
        residual, blocks = self.residual, self.blocks
        n_nodes, n_slots, n_elements, lanes = (self.n_nodes, len(self.slot), self.n_elements,
                                               self.lanes)
        get, put = self.accessors()
        # today's engine: one instance per iteration on plain scalars
        scalar = self.form == "instance_major"

        @ti.func
        def read(field: ti.template(), g, entry, component):
            """One instance's scalar (instance-major) or a group's lanes."""
            if ti.static(scalar):
                return field[g, entry, component]
            else:
                return get(field, g, entry, component)

        @ti.func
        def zero():
            if ti.static(scalar):
                return 0.0
            else:
                return ti.Vector([0.0] * lanes)

        @ti.func
        def store(field: ti.template(), g, entry, component, value):
            if ti.static(scalar):
                field[g, entry, component] = value
            else:
                put(field, g, entry, component, value)

        @ti.func
        def add(field: ti.template(), g, entry, component, value):
            store(field, g, entry, component, read(field, g, entry, component) + value)

        element = self._element(read, zero, add)

        @ti.func
        def assemble(g):
            for n, c in ti.ndrange(n_nodes, 2):
                store(residual, g, n, c, zero())
            for a, c in ti.ndrange(n_slots, 4):
                store(blocks, g, a, c, zero())
            for e in range(n_elements):
                element(g, e)

        return self.group_loop(assemble)

    def _element(self, read, zero, add):
        """A ti.func (g, e): element e of group (instance) g added into residual and blocks."""
        raise NotImplementedError


class LaneBending(LaneAssembly):
    """The bending term's assembly: the gradient as residual, the Hessian as Jacobian, per
    triplet `bend_element` on a `bending_chain`; element values (Δl, κ⁰, B)."""

    element_columns = 3

    def __init__(self, n_nodes: int, batch: int, form: str, lanes: int):
        super().__init__(n_nodes, batch, form, lanes, bending_chain(n_nodes))

    @staticmethod
    def state_of(n_nodes: int, count: int, seed: int):
        positions, element = bending_state(n_nodes, count, seed)
        return {"positions": positions}, element

    def derivative_error(self, state: dict, element: np.ndarray) -> float:
        return gradient_error(self, state["positions"], element)

    def _element(self, read, zero, add):
        positions, element = self.state["positions"], self.element
        residual, blocks = self.residual, self.blocks
        nodes, slots = self.element_nodes, self.element_slots

        @ti.func
        def triplet(g, t):
            i, j, k = nodes[t, 0], nodes[t, 1], nodes[t, 2]
            gradients, h11, h22, h12 = bend_element(
                read(positions, g, j, 0) - read(positions, g, i, 0),
                read(positions, g, j, 1) - read(positions, g, i, 1),
                read(positions, g, k, 0) - read(positions, g, j, 0),
                read(positions, g, k, 1) - read(positions, g, j, 1),
                read(element, g, t, 0), read(element, g, t, 1), read(element, g, t, 2))
            # node a's gradient Σ_p coupling[a][p]·g_p, and the 3 × 3 node blocks
            hessian = ((h11[0], h11[1], h11[1], h11[2]), (h12[0], h12[1], h12[2], h12[3]),
                       (h12[0], h12[2], h12[1], h12[3]), (h22[0], h22[1], h22[1], h22[2]))
            for a in ti.static(range(3)):
                node = nodes[t, a]
                for c in ti.static(range(2)):
                    value = zero()
                    for p in ti.static(range(2)):
                        if ti.static(BEND_COUPLING[a][p] != 0.0):
                            value += BEND_COUPLING[a][p] * gradients[2 * p + c]
                    add(residual, g, node, c, value)
            for a, b in ti.static(ti.ndrange(3, 3)):
                for c in ti.static(range(4)):
                    value = zero()
                    for p, q in ti.static(ti.ndrange(2, 2)):
                        weight = ti.static(BEND_COUPLING[a][p] * BEND_COUPLING[b][q])
                        if ti.static(weight != 0.0):
                            value += weight * hessian[2 * p + q][c]
                    add(blocks, g, slots[t, 3 * a + b], c, value)

        return triplet


RATE_GAIN = 1000.0
"""∂v/∂x of the rod drag's implicit velocity (1/s): implicit Euler's 1/h at the paper's 1-ms
step."""


@ti.func
def rod_drag_element(vx, vy, ex, ey, parallel_coeff, perpendicular_coeff):
    """The rod drag on one edge, F = −(c∥|a|a·t + c⊥|b|b·n) with a = v·t, b = v·n, t = e/|e|
    and n = t turned by +90°, and its derivatives ∂F/∂v (xx, xy, yy: symmetric) and ∂F/∂e
    (xx, xy, yx, yy), in the engine's closed form (`rod_drag`) written on components, so that
    every argument may be a scalar (one instance) or a ti.Vector of lanes: the same operations
    in the same order either way. v: the edge's mean velocity (m/s), e: its edge vector (m),
    c = ½·ρ_f·Δl̄·C (kg/m² per unit height). Returns ((Fx, Fy), ∂F/∂v, ∂F/∂e). A copy on
    components on purpose, as `bend_element` is."""
    length = ti.sqrt(ex * ex + ey * ey)
    tx, ty = ex / length, ey / length
    nx, ny = -ty, tx
    along = vx * tx + vy * ty
    across = vx * nx + vy * ny
    along_size, across_size = ti.abs(along), ti.abs(across)
    force = (-(parallel_coeff * along_size * along * tx + perpendicular_coeff * across_size
               * across * nx),
             -(parallel_coeff * along_size * along * ty + perpendicular_coeff * across_size
               * across * ny))
    d_velocity = (-2.0 * (parallel_coeff * along_size * tx * tx
                          + perpendicular_coeff * across_size * nx * nx),
                  -2.0 * (parallel_coeff * along_size * tx * ty
                          + perpendicular_coeff * across_size * nx * ny),
                  -2.0 * (parallel_coeff * along_size * ty * ty
                          + perpendicular_coeff * across_size * ny * ny))
    # ∂F/∂e = −(p·t + q·n)·nᵀ/|e|, rank one (the engine's `rod_drag` says why)
    tangent_weight = across * (2.0 * parallel_coeff * along_size
                               - perpendicular_coeff * across_size)
    normal_weight = along * (parallel_coeff * along_size - 2.0 * perpendicular_coeff * across_size)
    weighted_x = tangent_weight * tx + normal_weight * nx
    weighted_y = tangent_weight * ty + normal_weight * ny
    d_edge = (-(weighted_x * nx) / length, -(weighted_x * ny) / length,
              -(weighted_y * nx) / length, -(weighted_y * ny) / length)
    return force, d_velocity, d_edge


class LaneRodDrag(LaneAssembly):
    """The rod drag's assembly as the engine's term does it: on every edge of a chain, the drag
    on the mean implicit velocity of its two nodes, v = RATE_GAIN·(x − x_prev) + offset, half to
    each node (residual −F/2), its Jacobian on the edge's four blocks; element values
    (c∥, c⊥)."""

    node_fields = ("positions", "previous", "velocity_offset")
    element_columns = 2

    def __init__(self, n_nodes: int, batch: int, form: str, lanes: int):
        edges = np.stack([np.arange(n_nodes - 1), np.arange(1, n_nodes)], axis=1)
        super().__init__(n_nodes, batch, form, lanes, edges)

    @staticmethod
    def state_of(n_nodes: int, count: int, seed: int):
        return rod_drag_state(n_nodes, count, seed)

    def derivative_error(self, state: dict, element: np.ndarray) -> float:
        return rod_drag_jacobian_error(self, state, element)

    def _element(self, read, zero, add):
        positions, previous, offset = (self.state[name] for name in self.node_fields)
        element, residual, blocks = self.element, self.residual, self.blocks
        nodes, slots = self.element_nodes, self.element_slots

        @ti.func
        def velocity(g, node, c):
            return RATE_GAIN * (read(positions, g, node, c) - read(previous, g, node, c)) \
                + read(offset, g, node, c)

        @ti.func
        def edge(g, r):
            i, j = nodes[r, 0], nodes[r, 1]
            force, d_velocity, d_edge = rod_drag_element(
                0.5 * (velocity(g, i, 0) + velocity(g, j, 0)),
                0.5 * (velocity(g, i, 1) + velocity(g, j, 1)),
                read(positions, g, j, 0) - read(positions, g, i, 0),
                read(positions, g, j, 1) - read(positions, g, i, 1),
                read(element, g, r, 0), read(element, g, r, 1))
            for node in ti.static(range(2)):
                for c in ti.static(range(2)):
                    add(residual, g, nodes[r, node], c, -0.5 * force[c])
            d_v = (d_velocity[0], d_velocity[1], d_velocity[1], d_velocity[2])
            # the residual's derivative by node i (first) and node j (second): v is the mean
            # of both, e = x_j − x_i
            for c in ti.static(range(4)):
                first = -0.5 * (0.5 * RATE_GAIN * d_v[c] - d_edge[c])
                second = -0.5 * (0.5 * RATE_GAIN * d_v[c] + d_edge[c])
                for row in ti.static(range(2)):
                    add(blocks, g, slots[r, 2 * row], c, first)
                    add(blocks, g, slots[r, 2 * row + 1], c, second)

        return edge


def packed_ops(ir_folder: Path) -> dict[str, int]:
    """{"count": packed floating-point arithmetic instructions, "width": widest (lanes)} in the
    optimised LLVM IR files Taichi wrote into ir_folder since it was last emptied; empties it."""
    count, width = 0, 0
    for path in sorted(ir_folder.glob("*.ll")):
        for match in PACKED_OP.finditer(path.read_text(errors="replace")):
            count += 1
            width = max(width, int(match.group(1)))
        path.unlink()
    return {"count": count, "width": width}


def init_taichi(precision: str):
    """Taichi on the CPU as the engine runs it (no fast math), printing the optimised LLVM IR
    of every kernel it compiles into the working directory of the compilation (the callers
    compile inside `working_directory(ir_folder)`)."""
    with contextlib.redirect_stdout(io.StringIO()):
        ti.init(arch=ti.cpu, default_fp=ti.f64 if precision == "f64" else ti.f32,
                fast_math=False, offline_cache=False, log_level=ti.ERROR,
                print_kernel_llvm_ir_optimized=True)


@contextlib.contextmanager
def working_directory(folder: Path):
    previous = Path.cwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(previous)


def forms_of(lanes_list: list[int]):
    """(form, lanes) in the order they are timed: today's form first; the masked form only at
    the most lanes (what its cost is measured against)."""
    yield "instance_major", 1
    for form in ("unrolled_scalar", "lane_vector"):
        for lanes in lanes_list:
            yield form, lanes
    yield "lane_vector_masked", max(lanes_list)


def measure(plans: dict, precision: str, batch_sizes: list[int], lanes_list: list[int],
            repeats: int, matmul_size: int, ir_folder: Path) -> list[dict]:
    """Rows of simd.csv for one precision (see the module docstring)."""
    init_taichi(precision)
    rng = np.random.default_rng(0)
    rows = []
    for preset, plan in plans.items():
        flops = plan.factor_flops + solve_flops(plan)
        for batch in batch_sizes:
            distinct_blocks, distinct_rhs = random_system(plan, min(batch, DISTINCT_MATRICES),
                                                          seed=batch)
            repeat = -(-batch // len(distinct_blocks))
            blocks = np.tile(distinct_blocks, (repeat, 1, 1))[:batch]
            rhs = np.tile(distinct_rhs, (repeat, 1, 1))[:batch]
            systems, facts = {}, {}
            for form, lanes in forms_of(lanes_list):
                system = LaneSystem(plan, batch, form, lanes)
                system.load(blocks, rhs)
                system.restore()
                packed_ops(ir_folder)  # the IR of the copies is not the subject
                system.factor_solve()
                facts[form, lanes] = packed_ops(ir_folder)
                systems[form, lanes] = system
            load = os.getloadavg()[0]
            times = {key: [] for key in systems}
            best_matmul = 0.0
            for _ in range(repeats):
                best_matmul = max(best_matmul, matmul_gflops(matmul_size, precision, rng))
                for key, system in systems.items():
                    system.restore()
                    ti.sync()
                    start = time.perf_counter()
                    system.factor_solve()
                    ti.sync()
                    times[key].append(time.perf_counter() - start)
            reference = systems["instance_major", 1].solution()
            checked = sorted({0, batch // 2, batch - 1})[:CHECKED_INSTANCES]
            exact = [np.linalg.solve(dense_matrix(plan, blocks[b]), rhs[b].ravel())
                     for b in checked]
            for (form, lanes), system in systems.items():
                solution = system.solution()
                error = max(np.abs(solution[b].ravel() - x).max() / np.abs(x).max()
                            for b, x in zip(checked, exact))
                seconds = min(times[form, lanes])
                round_ratios = np.array(times["instance_major", 1]) / np.array(times[form, lanes])
                gflops = batch * flops / seconds / 1e9
                rows.append({
                    "preset": preset, "precision": precision, "batch_size": batch, "form": form,
                    "lanes": lanes, "n_nodes": plan.n_nodes, "n_slots": plan.n_slots,
                    "flops_per_instance": flops, "seconds": seconds,
                    "us_per_instance": seconds * 1e6 / batch, "gflops": gflops,
                    "matmul_gflops": best_matmul, "fraction_of_matmul": gflops / best_matmul,
                    "speedup_vs_instance_major": min(times["instance_major", 1]) / seconds,
                    "speedup_median_of_rounds": float(np.median(round_ratios)),
                    "packed_ops_in_ir": facts[form, lanes]["count"],
                    "vector_width_in_ir": facts[form, lanes]["width"],
                    "max_relative_error": float(error),
                    "bitwise_equal_to_instance_major": bool(np.array_equal(solution, reference)),
                    "load_average_1min": load})
                print(f"{preset} {precision} B={batch:>5} {form:>15} x{lanes}: "
                      f"{rows[-1]['us_per_instance']:8.2f} us/instance, {gflops:6.2f} GFLOP/s "
                      f"({rows[-1]['speedup_vs_instance_major']:.2f}x), packed ops "
                      f"{rows[-1]['packed_ops_in_ir']} (width {rows[-1]['vector_width_in_ir']})")
            for system in systems.values():
                system.destroy()
    return rows


def bend_energy(positions: np.ndarray, element: np.ndarray, triplets: np.ndarray) -> float:
    """NumPy: the chain's bending energy Σ ½·B·(κ − κ⁰)²·Δl (J/m) of one instance, positions
    (n_nodes, 2) m, element (T, 3) = (Δl, κ⁰, B) per triplet (`LaneBending.load`)."""
    e1 = positions[triplets[:, 1]] - positions[triplets[:, 0]]
    e2 = positions[triplets[:, 2]] - positions[triplets[:, 1]]
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    half_tangent = cross / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                            + (e1 * e2).sum(axis=1))
    length, natural, stiffness = element.T
    return float(0.5 * (stiffness * (2.0 * half_tangent / length - natural) ** 2 * length).sum())


def bending_state(n_nodes: int, count: int, seed: int):
    """(positions (count, n_nodes, 2), element (count, n_nodes − 2, 3)) of `count` chains: a
    10-cm rod of n_nodes bent in a wave of ±1 cm, every node moved by N(0, 0.1 mm), and per
    triplet its Voronoi length, a natural curvature uniform in ±50 1/m (the actuator's range)
    and the paper's arc stiffness B = E·r0³/12 (E = 5 MPa, r0 = 3.4 mm)."""
    rng = np.random.default_rng(seed)
    arc = np.linspace(0.0, 0.1, n_nodes)
    rod = np.stack([arc, 0.01 * np.sin(40.0 * arc)], axis=-1)
    positions = rod[None] + 1e-4 * rng.standard_normal((count, n_nodes, 2))
    element = np.empty((count, n_nodes - 2, 3))
    element[..., 0] = 0.1 / (n_nodes - 1)
    element[..., 1] = rng.uniform(-50.0, 50.0, (count, n_nodes - 2))
    element[..., 2] = 5e6 * 3.4e-3 ** 3 / 12.0
    return positions, element


def gradient_error(system: LaneBending, positions: np.ndarray, element: np.ndarray) -> float:
    """The largest error of instance 0's assembled gradient against central differences of
    `bend_energy` (f64, step 1e-8 m: truncation ~(1e-8/0.5e-3)² of the gradient, rounding
    ~1e-16·E/1e-8), relative to the gradient's largest entry."""
    step, reference = 1e-8, np.zeros_like(positions[0])
    for node, component in np.ndindex(*positions[0].shape):
        moved = [positions[0].copy(), positions[0].copy()]
        moved[0][node, component] += step
        moved[1][node, component] -= step
        reference[node, component] = (bend_energy(moved[0], element[0], system.elements)
                                      - bend_energy(moved[1], element[0], system.elements)
                                      ) / (2 * step)
    return float(np.abs(system.assembled_residual()[0] - reference).max()
                 / np.abs(reference).max())


def rod_drag_state(n_nodes: int, count: int, seed: int):
    """({"positions", "previous", "velocity_offset"} (count, n_nodes, 2), element (count,
    n_nodes − 1, 2)) of `count` chains: the rod of `bending_state` swimming at N(2, 5) cm/s per
    node and component (positions − previous = that velocity / RATE_GAIN), an integrator's
    offset of N(0, 1) cm/s, and per edge c∥ and c⊥ of the paper's drag coefficients (C∥ =
    0.01, C⊥ = 1) in water on its rest length (c = ½·ρ_f·Δl̄·C)."""
    rng = np.random.default_rng(seed)
    positions, _ = bending_state(n_nodes, count, seed)
    velocity = 0.02 + 0.05 * rng.standard_normal((count, n_nodes, 2))
    wetted = 0.5 * 1000.0 * 0.1 / (n_nodes - 1)
    element = np.empty((count, n_nodes - 1, 2))
    element[..., 0], element[..., 1] = wetted * 0.01, wetted * 1.0
    return {"positions": positions, "previous": positions - velocity / RATE_GAIN,
            "velocity_offset": 0.01 * rng.standard_normal((count, n_nodes, 2))}, element


def rod_drag_residual(state: dict, element: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """NumPy: one instance's rod drag residual (n_nodes, 2), N/m: −F/2 of every edge on each
    of its nodes (`LaneRodDrag`), from its node state {name: (n_nodes, 2)} and element (E, 2)."""
    velocity = RATE_GAIN * (state["positions"] - state["previous"]) + state["velocity_offset"]
    mean = 0.5 * (velocity[edges[:, 0]] + velocity[edges[:, 1]])
    edge = state["positions"][edges[:, 1]] - state["positions"][edges[:, 0]]
    tangent = edge / np.linalg.norm(edge, axis=1, keepdims=True)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    along, across = (mean * tangent).sum(axis=1), (mean * normal).sum(axis=1)
    force = -(element[:, :1] * (np.abs(along) * along)[:, None] * tangent
              + element[:, 1:] * (np.abs(across) * across)[:, None] * normal)
    residual = np.zeros_like(velocity)
    for node in (0, 1):
        np.add.at(residual, edges[:, node], -0.5 * force)
    return residual


def rod_drag_jacobian_error(system: LaneRodDrag, state: dict, element: np.ndarray) -> float:
    """The largest error of instance 0's assembled Jacobian (every block of the chain) against
    central differences of `rod_drag_residual` in the positions (f64, step 1e-8 m: the drag is
    quadratic in v, so only the tangent's curvature truncates, ~(1e-8/0.5e-3)²; the velocities
    move by 1e-5 m/s, far from the kink of |v·t| at the state's cm/s), relative to the
    Jacobian's largest entry."""
    step = 1e-8
    one = {name: values[0] for name, values in state.items()}
    n_nodes = system.n_nodes
    reference = np.zeros((2 * n_nodes, 2 * n_nodes))
    for node, component in np.ndindex(n_nodes, 2):
        moved = []
        for sign in (1.0, -1.0):
            shifted = dict(one, positions=one["positions"].copy())
            shifted["positions"][node, component] += sign * step
            moved.append(rod_drag_residual(shifted, element[0], system.elements).ravel())
        reference[:, 2 * node + component] = (moved[0] - moved[1]) / (2 * step)
    assembled = np.zeros_like(reference)
    blocks = system.jacobian_blocks()[0]
    for (row, column), slot in system.slot.items():
        assembled[2 * row:2 * row + 2, 2 * column:2 * column + 2] = blocks[slot].reshape(2, 2)
    return float(np.abs(assembled - reference).max() / np.abs(reference).max())


def repeated(values: np.ndarray, batch: int) -> np.ndarray:
    """The first `batch` of `values` (count, ...) repeated along the first axis."""
    return np.tile(values, (-(-batch // len(values)),) + (1,) * (values.ndim - 1))[:batch]


ASSEMBLIES = {"bending": LaneBending, "rod_drag": LaneRodDrag}
"""The assembly kernels of KERNELS and the term each times."""


def measure_assembly(kernel: str, plans: dict, precision: str, batch_sizes: list[int],
                     lanes_list: list[int], repeats: int, ir_folder: Path) -> list[dict]:
    """Rows of simd_assembly.csv for one assembly kernel (ASSEMBLIES) and one precision (module
    docstring)."""
    init_taichi(precision)
    assembly = ASSEMBLIES[kernel]
    rows = []
    for preset, plan in plans.items():
        for batch in batch_sizes:
            state, element = assembly.state_of(plan.n_nodes, min(batch, DISTINCT_MATRICES),
                                               seed=batch)
            state = {name: repeated(values, batch) for name, values in state.items()}
            element = repeated(element, batch)
            systems, facts = {}, {}
            for form, lanes in forms_of(lanes_list):
                system = assembly(plan.n_nodes, batch, form, lanes)
                system.load(state, element)
                packed_ops(ir_folder)
                system.assemble()
                facts[form, lanes] = packed_ops(ir_folder)
                systems[form, lanes] = system
            load = os.getloadavg()[0]
            times = {key: [] for key in systems}
            for _ in range(repeats):
                for key, system in systems.items():
                    ti.sync()
                    start = time.perf_counter()
                    system.assemble()
                    ti.sync()
                    times[key].append(time.perf_counter() - start)
            reference = systems["instance_major", 1]
            for (form, lanes), system in systems.items():
                seconds = min(times[form, lanes])
                round_ratios = np.array(times["instance_major", 1]) / np.array(times[form, lanes])
                rows.append({
                    "term": kernel, "preset": preset, "precision": precision, "batch_size": batch,
                    "form": form, "lanes": lanes, "n_nodes": plan.n_nodes,
                    "n_elements": system.n_elements,
                    "seconds": seconds, "us_per_instance": seconds * 1e6 / batch,
                    "speedup_vs_instance_major": min(times["instance_major", 1]) / seconds,
                    "speedup_median_of_rounds": float(np.median(round_ratios)),
                    "packed_ops_in_ir": facts[form, lanes]["count"],
                    "vector_width_in_ir": facts[form, lanes]["width"],
                    "derivative_relative_error": system.derivative_error(state, element),
                    "bitwise_equal_to_instance_major": bool(
                        np.array_equal(system.assembled_residual(),
                                       reference.assembled_residual())
                        and np.array_equal(system.jacobian_blocks(),
                                           reference.jacobian_blocks())),
                    "load_average_1min": load})
                print(f"{kernel} {preset} {precision} B={batch:>5} {form:>18} x{lanes}: "
                      f"{rows[-1]['us_per_instance']:8.2f} us/instance "
                      f"({rows[-1]['speedup_median_of_rounds']:.2f}x), packed ops "
                      f"{rows[-1]['packed_ops_in_ir']} (width {rows[-1]['vector_width_in_ir']})")
            for system in systems.values():
                system.destroy()
    return rows


def plot_speedups(csv_path, png_path):
    """One panel per preset and precision (and term, for simd_assembly.csv) from a simd CSV:
    each grouped form's speed-up over today's form (median of the rounds) against the batch
    size, one line per form and lane count, today's form the dashed line at 1."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    if "n_slots" not in table and "term" not in table:
        table["term"] = "bending"  # assembly tables from before the rod drag: bending alone
    keys = [key for key in ("term", "preset", "precision") if key in table]
    panels = list(table.groupby(keys, sort=False))
    columns = min(len(panels), 4)
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows), squeeze=False,
                             sharey=True, layout="constrained")
    for ax, (key, part) in zip(axes.flat, panels):
        for (form, lanes), line in part[part["form"] != "instance_major"].groupby(
                ["form", "lanes"], sort=False):
            line = line.sort_values("batch_size")
            ax.plot(line["batch_size"], line["speedup_median_of_rounds"], "o-",
                    label=f"{form} × {lanes}")
        ax.axhline(1.0, color="k", ls="--", lw=1, label="today's form")
        ax.set_xscale("log")
        ax.set_title(", ".join(str(value) for value in (key if isinstance(key, tuple) else (key,))),
                     fontsize=9)
        ax.set_xlabel("batch size B")
        ax.grid(alpha=0.3, which="both")
    for ax in axes[:, 0]:
        ax.set_ylabel("speed-up over today's form")
    for ax in list(axes.flat)[len(panels):]:
        ax.set_axis_off()
    axes.flat[0].legend(fontsize=7)
    made = cli.written_provenance(csv_path)
    if made:
        fig.suptitle(f"{made.get('machine', {}).get('cpu_model', '')}, commit "
                     f"{str(made.get('git_commit', ''))[:7]}", fontsize=9)
    cli.write_figure(fig, png_path, dpi=110)
    plt.close(fig)
    return png_path


def elimination_plans(presets: list[str]) -> dict:
    """{preset: the elimination plan of its engine's Newton matrix} (builds the engines)."""
    plans = {}
    for preset in presets:
        solver = SolverConfig.preset(preset, adaptive=False)
        plans[preset] = EngineProfile([StarParams.preset(preset)], solver).elimination_plan
    return plans


def kernel_words(kernel: str, plan) -> int:
    """The numbers one instance of `plan` (an elimination plan of a preset) holds for timing
    `kernel` (KERNELS): the LU's blocks and right-hand side, or an assembly's node state,
    element values, residual and chain blocks (`LaneAssembly`; as many elements as nodes, at
    most)."""
    if kernel == "factor_solve":
        return 4 * plan.n_slots + 2 * plan.n_nodes
    assembly = ASSEMBLIES[kernel]
    return (4 * len(chain_slots(plan.n_nodes)) + 2 * plan.n_nodes * (len(assembly.node_fields) + 1)
            + plan.n_nodes * assembly.element_columns)


def check_memory(plans: dict, batch_sizes: list[int], lanes_list: list[int],
                 kernels: list[str]):
    """StudyArgumentError naming --batch-sizes, before any timing or output, where the largest
    batch's systems of a kernel would not fit in memory (1,048,576 of the paper robot's LU
    systems took 52 GiB for one host copy and ended in NumPy's MemoryError, and the assemblies
    were not checked at all: audits, 2026-12): a kernel's timing holds about three float64
    host copies of its numbers (`kernel_words`) and every form's two Taichi copies at once,
    counted here in float64; the kernels are timed one after the other."""
    forms = len(list(forms_of(lanes_list)))
    largest = max(batch_sizes)
    for kernel in kernels:
        for preset, plan in plans.items():
            per_instance = 8 * kernel_words(kernel, plan) * (3 + 2 * forms)
            try:
                check_host_memory("--batch-sizes", f"{largest:,} {preset} systems of {kernel} "
                                  f"in {forms} forms", largest * per_instance,
                                  "give smaller --batch-sizes")
            except ValueError as error:
                raise cli.StudyArgumentError(str(error)) from None


def build_parser():
    parser = cli.StudyParser("simd", DESCRIPTION, archs=("cpu",))
    parser.add_argument("--presets", default="paper,accurate", quick="paper",
                        help=f"comma list of presets from {','.join(PRESETS)}")
    parser.add_argument("--precisions", default="f64,f32",
                        help="comma list of f64 and/or f32")
    parser.add_argument("--batch-sizes", default="64,512,4096", quick="8,16",
                        help=f"comma list of batch sizes, each in [1, {cli.MAX_BATCH_SIZE}] "
                             f"(multiples of every lane count)")
    parser.add_argument("--lanes", default="4,8", quick="4",
                        help=f"comma list of instances per loop iteration of the grouped forms, "
                             f"each in [1, {MAX_LANES}]")
    parser.add_argument("--repeats", type=int, default=7, quick=2,
                        help=f"interleaved timing rounds (each form's best is kept; at most "
                             f"{cli.MAX_REPEATS})")
    parser.add_argument("--matmul-size", type=int, default=1024, quick=256,
                        help=f"n of NumPy's n × n reference matrix product (16 to "
                             f"{MAX_MATMUL_SIZE})")
    parser.add_argument("--kernels", default=",".join(KERNELS),
                        help=f"comma list of the kernels to time, from {','.join(KERNELS)}")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    presets = cli.parse_choices(args.presets, "--presets", PRESETS)
    precisions = cli.parse_choices(args.precisions, "--precisions", PRECISIONS)
    batch_sizes = cli.parse_counts(args.batch_sizes, "--batch-sizes", cli.MAX_BATCH_SIZE)
    lanes_list = cli.parse_counts(args.lanes, "--lanes", MAX_LANES)
    kernels = cli.parse_choices(args.kernels, "--kernels", KERNELS)
    for batch in batch_sizes:
        if any(batch % lanes for lanes in lanes_list):
            raise cli.StudyArgumentError(f"--batch-sizes: {batch} is not a multiple of every "
                                         f"--lanes value ({args.lanes})")
    cli.check_count(args.repeats, "--repeats", 1, cli.MAX_REPEATS)
    if not 16 <= args.matmul_size <= MAX_MATMUL_SIZE:
        raise cli.StudyArgumentError(f"--matmul-size must be in [16, {MAX_MATMUL_SIZE}], got "
                                     f"{args.matmul_size}")
    plans = elimination_plans(presets)
    check_memory(plans, batch_sizes, lanes_list, kernels)
    out = cli.Output(args, argv or [], model={"presets": presets},
                     extra={"precisions": precisions, "batch_sizes": batch_sizes,
                            "lanes": lanes_list, "repeats": args.repeats,
                            "matmul_size": args.matmul_size, "kernels": kernels,
                            "cpu_model": cpu_model(),
                            "cores": os.cpu_count()})
    rows = {kernel: [] for kernel in kernels}
    try:
        with tempfile.TemporaryDirectory(prefix="simd-ir-") as ir_folder:
            for precision in precisions:
                with working_directory(Path(ir_folder)):  # where Taichi writes the IR
                    if "factor_solve" in kernels:
                        rows["factor_solve"] += measure(plans, precision, batch_sizes,
                                                        lanes_list, args.repeats,
                                                        args.matmul_size, Path(ir_folder))
                    for kernel in ASSEMBLIES:
                        if kernel in kernels:
                            rows[kernel] += measure_assembly(kernel, plans, precision,
                                                             batch_sizes, lanes_list,
                                                             args.repeats, Path(ir_folder))
    finally:
        # this study initialised Taichi itself: the next simulation initialises it again,
        # taking this program for the package's own, not a user's (no warning)
        Runtime.current().configure_compiler()
        Runtime.current().adopt_program()
    tables = {}
    if "factor_solve" in kernels:
        tables["simd.csv"] = pd.DataFrame(rows["factor_solve"])
    assembly_rows = [row for kernel in ASSEMBLIES if kernel in kernels for row in rows[kernel]]
    if assembly_rows:
        tables["simd_assembly.csv"] = pd.DataFrame(assembly_rows)
    for name in {"simd.csv", "simd_assembly.csv"} - set(tables):
        # a run of the LU alone left an earlier run's assembly table beside its own (an audit,
        # 2026-12), and the other way round
        out.remove_earlier(name, name.replace(".csv", ".png"))
    for name, table in tables.items():
        # the machine and the code on every row (in the sidecar alone before: an audit, 2026-12)
        csv_path = out.write_csv(table.assign(**provenance.timing_columns("cpu")), name)
        out.wrote(plot_speedups(csv_path, out.path(name.replace(".csv", ".png"))))
    out.report()
    return next(iter(tables.values()))
