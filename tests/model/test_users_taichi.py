"""taichi_star beside a user's own Taichi code in one process: Taichi holds one program per
process, and `ti.init` destroys the one before with its fields and kernels. A `simulate` after
the user's `ti.init` warns that the user's program is destroyed; a `ti.init` after a
simulation makes the next `simulate` start Taichi again instead of running engines of the
destroyed program (both aborted the process: an audit, 2026-12), and warn as the first did (a
review), and a Simulator or an EngineProfile built before it refuses to step, also once
Taichi has been started again for a later simulation or by the package's own kernels. Run in
a fresh process, whose Taichi nothing else has started."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent('''
    import gc
    import warnings

    import taichi as ti
    import taichi_star as ts

    # the paper robot and solver: engines the other tests build, whose kernels the offline
    # cache then holds (a robot of its own compiled for seconds)
    robot = [ts.StarParams(gait="A1")]
    solver = ts.SolverConfig()
    ti.init(arch=ti.cpu)
    ti.field(ti.f32, shape=4).fill(1.0)  # the user's program, with a field in it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = ts.simulate(robot, 0.02, solver, progress=False).summary
    print("warned:", any("already started outside taichi_star" in str(w.message)
                         for w in caught))
    ti.init(arch=ti.cpu)  # the user's again: taichi_star's engines are gone
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        again = ts.simulate(robot, 0.02, solver, progress=False).summary
    print("warned again:", any("already started outside taichi_star" in str(w.message)
                               for w in caught))
    print("same bits:", again.drop(columns="actuator_profile").equals(
        first.drop(columns="actuator_profile")))
    # a Simulator and an EngineProfile, each built and then left by a user's ti.init
    for name, build, step in (("simulator", ts.Simulator, lambda held: held.advance(0.01)),
                              ("profile", ts.EngineProfile, lambda held: held.advance(2))):
        held = build(robot, solver)
        ti.init(arch=ti.cpu)
        try:
            step(held)
        except RuntimeError as error:
            print(name, "refused:",
                  "build the Simulator (environment, EngineProfile) again" in str(error))
        del held
        gc.collect()
    print("after:", ts.simulate(robot, 0.02, solver, progress=False).summary.status.tolist())
    # a Simulator alive through Taichi started again, by the user or by the package's own
    # kernels (the simd study's ti.init, then adopt_program): it refuses to step, before and
    # after a simulate that starts Taichi again for itself, which the dead Simulator does not
    # hold back (it was refused "would destroy them"; adopting ran the destroyed engine)
    from taichi_star.runtime import Runtime
    for name, restart in (("user's", lambda: None),
                          ("package's", lambda: Runtime.current().adopt_program())):
        held = ts.Simulator(robot, solver)
        ti.init(arch=ti.cpu)
        restart()
        for when in ("before", "after"):
            try:
                held.advance(0.01)
                print(name, when, "stepped")
            except RuntimeError as error:
                print(name, when, "refused:", "build the Simulator" in str(error))
            if when == "before":
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    status = ts.simulate(robot, 0.02, solver, progress=False).summary.status
                print(name, "simulate:", status.tolist(), "warned:",
                      any("already started" in str(w.message) for w in caught))
        del held
        gc.collect()
''')


def test_a_users_ti_init_before_or_after_a_simulation_is_warned_or_survived(tmp_path):
    script = tmp_path / "users_taichi.py"
    script.write_text(SCRIPT)
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode == 0, run.stderr[-3000:]
    lines = [line for line in run.stdout.splitlines() if not line.startswith("[Taichi]")]
    assert lines == ["warned: True", "warned again: True", "same bits: True",
                     "simulator refused: True", "profile refused: True", "after: ['ok']",
                     "user's before refused: True", "user's simulate: ['ok'] warned: True",
                     "user's after refused: True",
                     "package's before refused: True",
                     "package's simulate: ['ok'] warned: False",
                     "package's after refused: True"], \
        run.stdout + run.stderr[-3000:]
