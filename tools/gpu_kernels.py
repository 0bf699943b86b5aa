"""The accurate preset's two step kernels on a GPU, for a profiler to read (tools/gpu_session.sh
occupancy runs this under Nsight Compute): `simulate` of B instances of the accurate preset for
a few steps with its adaptive solver, then with fixed steps of the same model, so that one
launch of each (`advance_adaptive`, `advance`) can be profiled.

    python tools/gpu_kernels.py [--arch gpu] [--batch 8192] [--duration 0.02]
"""

import argparse

import taichi_star as ts


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arch", default="gpu")
    parser.add_argument("--batch", type=int, default=8192)
    parser.add_argument("--duration", type=float, default=0.02)
    args = parser.parse_args()
    params = [ts.StarParams.preset("accurate", gait="A1+A3")] * args.batch
    adaptive = ts.SolverConfig.preset("accurate")
    fixed = ts.SolverConfig.preset("accurate", adaptive=False, dt=1e-3, jacobian="newton")
    for solver in (adaptive, fixed):
        summary = ts.simulate(params, args.duration, solver=solver, arch=args.arch,
                              progress=False).summary
        print(f"adaptive={solver.adaptive}: {summary['steps'].mean():.1f} steps, "
              f"{summary['newton_iterations_mean'].mean():.2f} Newton updates a step, "
              f"status {sorted(set(summary['status']))}", flush=True)


if __name__ == "__main__":
    main()
