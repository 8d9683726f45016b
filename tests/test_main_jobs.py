"""The README's main job and the benchmark CLI run end to end (output checked, never timed)."""

import numpy as np
import sapien
from PIL import Image

from mani_skill_space import bench, showcase


def test_showcase_writes_a_picture_grid_and_a_video_per_domain(tmp_path, capsys):
    args = showcase.Args(output_dir=tmp_path, steps=2, image_size=64)
    showcase.main(args)
    rows = 0
    for env_id in args.env_ids:
        for domain in showcase.task_class(env_id).SUPPORTED_DOMAINS:
            assert (tmp_path / f"{env_id}_{domain}.mp4").stat().st_size > 1000
            rows += 1
    picture = np.asarray(Image.open(tmp_path / "first_frames.png"))
    assert picture.shape == (64 * rows, 64 * 2, 3)
    assert picture.std() > 10
    printed = capsys.readouterr().out
    assert str(tmp_path / "first_frames.png") in printed


def test_bench_prints_a_table_with_ratios_against_maniskill(capsys):
    report = bench.main(bench.Args(obs_modes=("state",), steps=5, rounds=1, reconfigures=1, asset_repeats=1, vector_workers=0))
    names = [row.name for row in report.rows]
    assert any("env.step" in n for n in names) and any("reconfigure" in n for n in names)
    assert all(row.reference_name == bench.REFERENCES[row.name.split()[0]] and row.ours > 0 and row.reference > 0 for row in report.rows)
    assert {r.name.split()[0] for r in report.rows} == set(bench.REFERENCES)
    assert {"rock (lunar)", "rock (martian)", "terrain (moon)", "rover", "peg and hole pair (procedural)"} <= set(report.assets_ms)
    table = capsys.readouterr().out
    assert "| SampleCollection-v1 env.step/s (state) |" in table and "x |" in table


def test_bench_vector_row_steps_two_spawned_workers_of_ours_and_of_the_reference():
    args = bench.Args(env_ids=("SampleCollection-v1",), obs_modes=("state",), steps=3, rounds=1, reconfigures=1, asset_repeats=1, vector_workers=2)
    (row,) = [row for row in bench.main(args).rows if "AsyncVectorEnv" in row.name]
    assert row.name.startswith("SampleCollection-v1 AsyncVectorEnv x2") and row.reference_name == "PickCube-v1"
    assert row.ours > 0 and row.reference > 0


def test_procedural_variety_picture_has_a_panel_per_kind_and_differs_by_seed():
    # as an env with ManiSkill's "minimal" shader pack leaves SAPIEN's process-wide settings (8-bit colour)
    sapien.render.set_camera_shader_dir("minimal")
    sapien.render.set_picture_format("Color", "r8g8b8a8unorm")
    picture = showcase.procedural_variety(count=4, solar_count=1, panel_size=96)
    assert picture.shape == (96, 4 * 96, 3) and picture.dtype == np.uint8
    panels = np.split(picture[20:], 4, axis=1)  # below the labels
    assert all(panel.std() > 5 for panel in panels)
    assert not np.array_equal(picture, showcase.procedural_variety(count=4, solar_count=1, panel_size=96, seed=1))
