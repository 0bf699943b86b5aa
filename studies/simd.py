"""SIMD across instances: does grouping instances into vector lanes speed up the CPU's block LU?

    python -m studies simd [--presets paper,accurate] [--precisions f64,f32]
                           [--batch-sizes 64,512,4096] [--lanes 4,8] [--repeats 7]
                           [--matmul-size 1024] [--out DIR] [--quick]

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

Writes `simd.csv`: one row per preset, precision, batch size and form: n_nodes, n_slots (2×2
blocks with fill-in), lanes, flops_per_instance (factor + solve), seconds (best), us_per_instance,
gflops, matmul_gflops (NumPy, best in the same rounds), fraction_of_matmul,
speedup_vs_instance_major, speedup_median_of_rounds, packed_ops_in_ir (packed floating-point
arithmetic instructions in the kernel's optimised IR), vector_width_in_ir (widest packed type
found, lanes; 0: none), max_relative_error (the solution against `numpy.linalg.solve` on the
dense matrix of checked instances), bitwise_equal_to_instance_major (every instance's solution),
load_average_1min (before the row's timings).

--quick: the paper pattern, B = 8 and 16, f64 and f32, lanes 4, two repeats, 256 × 256 matmul.
"""

import contextlib
import io
import math
import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import taichi as ti

from taichi_star import PRESETS, EngineProfile, SolverConfig, StarParams
from taichi_star.runtime import PARALLEL_LOOP_MINIMUM, Runtime

from . import cli, provenance

DESCRIPTION = ("SIMD across instances: the Newton matrix's block LU in today's layout against "
               "lane-grouped forms, with the LLVM IR checked for vector instructions.")
FORMS = ("instance_major", "unrolled_scalar", "lane_vector", "lane_vector_masked")
VECTOR_FORMS = ("lane_vector", "lane_vector_masked")
"""The forms whose field elements are ti.Vectors of lanes."""
PRECISIONS = ("f64", "f32")
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


class LaneSystem:
    """The block LU of `plan` for `batch` instances in `form` (FORMS) with `lanes` instances per
    loop iteration (1 for instance_major), in the current Taichi precision. Fields in one SNode
    tree of their own (`destroy` frees it)."""

    def __init__(self, plan, batch: int, form: str, lanes: int):
        if batch % lanes:
            raise ValueError(f"batch: a multiple of lanes = {lanes}, got {batch}")
        self.plan, self.batch, self.form, self.lanes = plan, batch, form, lanes
        self.groups = batch // lanes
        builder = ti.FieldsBuilder()
        self.blocks, self.pristine_blocks = (self._field(builder, plan.n_slots, 4)
                                             for _ in range(2))
        self.rhs, self.pristine_rhs = (self._field(builder, plan.n_nodes, 2) for _ in range(2))
        self.active = ti.Vector.field(lanes, ti.i32)
        builder.dense(ti.i, self.groups).place(self.active)
        tables = {name: np.ascontiguousarray(getattr(plan, name), dtype=np.int32)
                  for name in ("order", "pivot_slot", "neighbour_start", "neighbour_node",
                               "lower_slot", "upper_slot", "update_start", "update_slot")}
        self.tables = {}
        for name, values in tables.items():
            self.tables[name] = ti.field(ti.i32)
            builder.dense(ti.i, max(len(values), 1)).place(self.tables[name])
        self.tree = builder.finalize()
        for name, values in tables.items():
            self.tables[name].from_numpy(values if len(values) else np.zeros(1, np.int32))
        self.active.from_numpy(np.ones((self.groups, lanes), dtype=np.int32))
        self.factor_solve, self.restore = self._kernels()

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
            return values
        grouped = values.reshape(self.groups, self.lanes, *values.shape[1:])
        return np.ascontiguousarray(np.moveaxis(grouped, 1, -1))

    def from_layout(self, values: np.ndarray) -> np.ndarray:
        if self.form not in VECTOR_FORMS:
            return values
        return np.moveaxis(values, -1, 1).reshape(self.batch, *values.shape[1:3])

    def load(self, blocks: np.ndarray, rhs: np.ndarray):
        """Set the matrices (batch, n_slots, 4) and right-hand sides (batch, n_nodes, 2)."""
        self.pristine_blocks.from_numpy(self.to_layout(blocks.astype(self._dtype())))
        self.pristine_rhs.from_numpy(self.to_layout(rhs.astype(self._dtype())))

    def solution(self) -> np.ndarray:
        """(batch, n_nodes, 2) the right-hand sides after factor_solve: the solutions."""
        return self.from_layout(self.rhs.to_numpy())

    @staticmethod
    def _dtype():
        return np.float64 if ti.lang.impl.get_runtime().default_fp == ti.f64 else np.float32

    def destroy(self):
        self.tree.destroy()

    def _kernels(self):
        lanes, form, plan = self.lanes, self.form, self.plan
        blocks, rhs, pristine_blocks, pristine_rhs = (self.blocks, self.rhs, self.pristine_blocks,
                                                      self.pristine_rhs)
        active = self.active
        t = self.tables
        n_nodes = plan.n_nodes

        # a block of a group is a 4 × lanes matrix: its components a00, a01, a10, a11 (rows)
        # for every lane (columns); Taichi unrolls all of it into scalar code
        @ti.func
        def get(field: ti.template(), g, entry, component):
            """The lanes of group g: a ti.Vector of `lanes` scalars."""
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

        # one group per task, and the groups spread over at least PARALLEL_LOOP_MINIMUM loop
        # iterations as the engine spreads its instances: Taichi's CPU backend runs a shorter
        # parallel loop on one thread, which would favour whichever form has more iterations
        spread = max(1, -(-PARALLEL_LOOP_MINIMUM // self.groups))
        groups = self.groups

        @ti.kernel
        def factor_solve():
            ti.loop_config(block_dim=1)
            for slot in range(groups * spread):
                if slot % spread == 0:
                    factor(slot // spread)
                    solve(slot // spread)

        @ti.kernel
        def restore():
            ti.loop_config(block_dim=1)
            for slot in range(groups * spread):
                if slot % spread == 0:
                    g = slot // spread
                    for entry, component in ti.ndrange(plan.n_slots, 4):
                        put(blocks, g, entry, component,
                            get(pristine_blocks, g, entry, component))
                    for entry, component in ti.ndrange(n_nodes, 2):
                        put(rhs, g, entry, component, get(pristine_rhs, g, entry, component))

        return factor_solve, restore


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


def init_taichi(precision: str, ir_folder: Path):
    """Taichi on the CPU as the engine runs it (no fast math), printing the optimised LLVM IR
    of every kernel it compiles into ir_folder (the working directory while compiling)."""
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


def matmul_gflops(size: int, precision: str, rng) -> float:
    """NumPy's size × size matrix product in precision, GFLOP/s (best of 3)."""
    dtype = np.float64 if precision == "f64" else np.float32
    a, b = (rng.standard_normal((size, size)).astype(dtype) for _ in range(2))
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        np.dot(a, b)
        best = min(best, time.perf_counter() - start)
    return 2 * size ** 3 / best / 1e9


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
    init_taichi(precision, ir_folder)
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


def elimination_plans(presets: list[str]) -> dict:
    """{preset: the elimination plan of its engine's Newton matrix} (builds the engines)."""
    plans = {}
    for preset in presets:
        solver = SolverConfig.preset(preset, adaptive=False)
        plans[preset] = EngineProfile([StarParams.preset(preset)], solver).elimination_plan
    return plans


def build_parser():
    parser = cli.StudyParser("simd", DESCRIPTION, archs=("cpu",))
    parser.add_argument("--presets", default="paper,accurate", quick="paper",
                        help=f"comma list of presets from {','.join(PRESETS)}")
    parser.add_argument("--precisions", default="f64,f32",
                        help="comma list of f64 and/or f32")
    parser.add_argument("--batch-sizes", default="64,512,4096", quick="8,16",
                        help="comma list of batch sizes (multiples of every lane count)")
    parser.add_argument("--lanes", default="4,8", quick="4",
                        help="comma list of instances per loop iteration of the grouped forms")
    parser.add_argument("--repeats", type=int, default=7, quick=2,
                        help="interleaved timing rounds (each form's best is kept)")
    parser.add_argument("--matmul-size", type=int, default=1024, quick=256,
                        help="n of NumPy's n × n reference matrix product")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    presets = cli.parse_choices(args.presets, "--presets", PRESETS)
    precisions = cli.parse_choices(args.precisions, "--precisions", PRECISIONS)
    batch_sizes = cli.parse_counts(args.batch_sizes, "--batch-sizes")
    lanes_list = cli.parse_counts(args.lanes, "--lanes")
    for batch in batch_sizes:
        if any(batch % lanes for lanes in lanes_list):
            raise cli.StudyArgumentError(f"--batch-sizes: {batch} is not a multiple of every "
                                         f"--lanes value ({args.lanes})")
    for value, flag, low in ((args.repeats, "--repeats", 1), (args.matmul_size,
                                                               "--matmul-size", 16)):
        if value < low:
            raise cli.StudyArgumentError(f"{flag} must be >= {low}, got {value}")
    out = cli.Output(args, argv or [], model={"presets": presets},
                     extra={"precisions": precisions, "batch_sizes": batch_sizes,
                            "lanes": lanes_list, "repeats": args.repeats,
                            "matmul_size": args.matmul_size, "cpu_model": provenance.cpu_model(),
                            "cores": os.cpu_count()})
    plans = elimination_plans(presets)
    rows = []
    try:
        with tempfile.TemporaryDirectory(prefix="simd-ir-") as ir_folder:
            for precision in precisions:
                with working_directory(Path(ir_folder)):  # where Taichi writes the IR
                    rows += measure(plans, precision, batch_sizes, lanes_list, args.repeats,
                                    args.matmul_size, Path(ir_folder))
    finally:
        # this study initialised Taichi itself: the next simulation initialises it again
        Runtime.current().configure_compiler()
    table = pd.DataFrame(rows)
    out.write_csv(table, "simd.csv")
    out.report()
    return table
