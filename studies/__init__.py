"""Runnable studies over taichi_star: `python -m studies <name> [--arch cpu|gpu] [--out DIR]
[--quick] ...`. Each study is a module with `main(argv)`: parameters -> one `simulate` batch
(chunked when large) -> one DataFrame -> CSV -> plots drawn from that CSV.

Studies: fig4c (the paper's Fig. 4c/4b), sweep (parameter sensitivity), gaits (all 255 gaits by
symmetry class), calibrate (CMA-ES fit of any parameters to the experiment, leave-one-gait-out
cross-validation), sensitivity (Sobol indices of each gait's speed), animate (GIF of a
cycle), bench (engine throughput), work_precision (run time against error), primitives
(every gait's per-cycle step and turn), plan (open- and closed-loop driving to goals), env_bench (vector environment
throughput).
"""

STUDIES = {
    "fig4c": "the paper's Fig. 4c/4b: five gaits, simulation vs experiment",
    "sweep": "sensitivity: Cartesian product of parameter lists/ranges",
    "gaits": "all 255 gaits, one simulation per symmetry class, ranked",
    "calibrate": "CMA-ES fit of StarParams fields to the measured speeds; --cross-validate",
    "sensitivity": "Sobol indices (Saltelli sampling) of each gait's signed speed",
    "animate": "GIF of the robot's shape over one cycle",
    "bench": "engine throughput: robot-steps/s against batch size and precision",
    "work_precision": "run time against error: h, precision, tolerance, discretisation, integrator",
    "convergence": "speed against n_arc, clamped vs shared actuation ends, the converged preset",
    "stability": "stress grid: dt x stiffness x alpha x C_a x period x gait x precision; outcome maps",
    "scaling": "wall time of one fixed sweep: in process against 1, 2, ... local Dask workers",
    "primitives": "every gait's steady per-cycle step (body frame) and turn; polar plot",
    "plan": "drive the robot to goals by choosing a gait per cycle: open vs closed loop",
    "env_bench": "vector environment throughput: simulated robot-seconds per wall second",
}
