"""`safl-bench data export`: scans in BEVPlace's image layout, read back by the top-view source."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safl_bench.cli import main
from safl_bench.mapbuild import build_views
from safl_bench.mapconfig import bev_density_config
from safl_bench.sources import bev_source, kitti_source
from safl_bench.views.render import build_views as render_views


def test_export_round_trip(kitti_root: Path, safl_home: Path, tmp_path: Path,
                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bev"
    argv = ["data", "export", "--kitti-root", str(kitti_root), "--sequence", "00", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    assert "12 151x151 bev-density images" in capsys.readouterr().out
    files = sorted((out / "00" / "imgs").glob("*.png"))
    assert [f.name for f in files] == [f"{i:06d}.png" for i in range(12)]
    kitti = kitti_source(kitti_root).sequence("00")
    bev = bev_source(out).sequence("00")
    assert len(bev) == 12 and not bev.times_assumed
    np.testing.assert_allclose(bev.positions, kitti.positions, atol=1e-6)
    np.testing.assert_allclose(bev.headings, kitti.headings, atol=1e-6)
    np.testing.assert_allclose(bev.times, kitti.times)
    views = render_views(bev_source(out), "00", None, np.arange(12), {"c": None})["c", "topview"]
    expect = build_views(kitti, bev_density_config(), np.arange(12), {"c": None}, progress=False)["c", "topview"]
    np.testing.assert_array_equal(views, expect)  # the PNGs hold the views exactly

    # a non-empty folder is never overwritten without --force: one line, exit 2
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "is not empty" in err and "--force" in err and str(out / "00") in err
    # with --force the earlier images go, every 5th frame is written, frames.txt says which
    assert main([*argv, "--force", "--step", "5"]) == 0
    assert len(list((out / "00" / "imgs").glob("*.png"))) == 3
    assert (out / "00" / "frames.txt").read_text().split() == ["0", "5", "10"]
    again = bev_source(out).sequence("00")
    np.testing.assert_allclose(again.positions, kitti.positions[[0, 5, 10]], atol=1e-6)


def test_export_bad_input(kitti_root: Path, safl_home: Path, tmp_path: Path,
                          capsys: pytest.CaptureFixture[str]) -> None:
    base = ["data", "export", "--kitti-root", str(kitti_root), "--out", str(tmp_path / "x"), "--quiet"]
    assert main([*base, "--sequence", "07"]) == 2
    assert "no such sequence" in capsys.readouterr().err
    assert main([*base, "--step", "0"]) == 2
    assert "--step" in capsys.readouterr().err


def test_show_compares_density_views_with_an_image_folder(kitti_root: Path, safl_home: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    bev = tmp_path / "bev"
    assert main(["data", "export", "--kitti-root", str(kitti_root), "--out", str(bev), "--quiet"]) == 0
    png = tmp_path / "show.png"
    argv = ["data", "show", "--kitti-root", str(kitti_root), "--frames", "3", "9", "--bev-root", str(bev),
            "--out", str(png)]
    assert main(argv) == 0 and png.is_file()
    out = capsys.readouterr().out
    assert out.count("IoU 1.0000, equal pixels 100.0000%") == 2
    assert main([*argv[:-2], "--frames", "12", "--out", str(png)]) == 2
    assert "--frames" in capsys.readouterr().err
