"""The animate study's GIFs are drawn from its tables as written: shapes.csv and centroid.csv,
read back, redraw each GIF frame for frame; edges.csv is the library's edge table."""

import numpy as np
import pandas as pd
from PIL import Image, ImageSequence

import taichi_star
from taichi_star import SolverConfig, StarParams
from taichi_star.output import edge_table, replay

from studies import animate, cli

GAITS = ["A1", "A1+A2"]


def gif_frames(path) -> np.ndarray:
    """(frames, height, width, 3) RGB of a GIF."""
    with Image.open(path) as gif:
        return np.stack([np.asarray(frame.convert("RGB")) for frame in ImageSequence.Iterator(gif)])


def test_each_gif_is_redrawn_from_the_tables_alone(tmp_path):
    """The tables (each with its provenance sidecar) replayed into another run of the same
    robots, one recorded at its start and end alone (2 records, the study's 6), give the
    study's GIFs pixel for pixel: every frame comes from the tables."""
    animate.main(["--out", str(tmp_path), "--frames", "5", "--gait", ",".join(GAITS),
                  "--quick", "--no-progress"])
    folder = tmp_path / "animations"
    for name in ("shapes.csv", "centroid.csv", "edges.csv"):
        assert (folder / name).is_file() and (folder / f"{name}.json").is_file(), name
    pd.testing.assert_frame_equal(pd.read_csv(folder / "edges.csv"), edge_table(StarParams()),
                                  check_dtype=False)
    shapes = pd.read_csv(folder / "shapes.csv")
    assert shapes["gait"].unique().tolist() == GAITS and shapes["frame"].max() == 5
    other = taichi_star.simulate([StarParams(gait=g) for g in GAITS], cli.QUICK_DURATION_S,
                                 SolverConfig(dt=cli.QUICK_DT),
                                 record_interval_s=cli.QUICK_DURATION_S, record_shapes=True)
    assert other.shapes.shape[0] == 2
    drawn = replay(other, shapes, pd.read_csv(folder / "centroid.csv"))
    # a whole result: its headings NaN (the tables hold none), its xarray form made (without
    # the column it failed; an audit, 2026-12)
    assert drawn.to_xarray().sizes["instance"] == len(GAITS)
    for instance, gait in enumerate(GAITS):
        name = f"{gait.replace('+', '_')}.gif"
        drawn.animate(tmp_path / name, instances=[instance], fps=15, size_px=600,
                      title=f"gait {gait}")
        study, again = gif_frames(folder / name), gif_frames(tmp_path / name)
        assert len(study) == 6
        np.testing.assert_array_equal(again, study, err_msg=gait)

