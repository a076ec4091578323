"""Fidelity statistics on tiny hand-made data, and the `data fidelity` command's bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from safl_bench import fidelity as F
from safl_bench.cli import main
from safl_bench.errors import DataError


def _image(seed: int, size: int = 64, density: float = 0.1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.where(rng.random((size, size)) < density, rng.integers(1, 11, (size, size)) * 25.5, 0).astype(np.uint8)


def test_image_stats_of_hand_made_images() -> None:
    images = np.zeros((2, 5, 5), np.uint8)
    images[0, 2, 2] = 255  # the centre pixel
    images[1, 0, 2] = 51   # 2 pixels (0.8 m) ahead
    st = F.image_stats(images, resolution_m=0.4, edges_m=(0.0, 0.5, 1.0))
    assert st.nonzero_fraction == pytest.approx(2 / 50)
    assert st.mean_nonzero == pytest.approx((1.0 + 0.2) / 2)
    # the mean image: 0.5 at the centre, 0.1 at the pixel 0.8 m ahead; ring 0 (< 0.5 m) holds the
    # centre and its 4 neighbours (0.4 m), ring 1 (0.5-1 m) 4 diagonals (0.57 m), 4 pixels at
    # 0.8 m and 8 at 0.89 m
    assert st.radial_profile[0] == pytest.approx(0.5 / 5)
    assert st.radial_profile[1] == pytest.approx(0.1 / 16)


def test_lateral_occupancy_of_hand_made_images() -> None:
    # 11 x 11 pixels of 0.4 m, the sensor at pixel (5, 5); a pixel 1.2 m left of it counts, one
    # 2 m ahead (outside the 0.4 m band) does not; left is a smaller column (BEVPlace's layout)
    images = np.zeros((1, 11, 11), np.uint8)
    images[0, 5, 2] = 10
    images[0, 0, 8] = 10
    st = F.image_stats(images, resolution_m=0.4, edges_m=(0.0, 1.0), lateral_edges_m=(-2.0, 0.0, 2.0),
                       band_m=0.4)
    assert st.lateral_edges_m == [-2.0, 0.0, 2.0]
    # band: rows 4-6; right bin: columns 6-10 (y -0.4..-2.0 m), left bin: columns 1-5 (y 1.6..0 m)
    assert st.lateral_occupancy == [pytest.approx(0.0), pytest.approx(1 / 3 / 5)]


def test_distance_and_heading_curves_of_hand_made_images() -> None:
    a, b, c = _image(1), _image(2), _image(3)
    a2 = a.copy()
    a2[10:20, 10:20] = 255  # a changed view of place A
    images = np.stack([a, a, b, b, c, a2])
    positions = np.array([[0, 0], [1, 0], [150, 0], [151, 0], [300, 0], [5, 0]], float)
    headings = np.radians([0, 100, 0, 0, 0, 0])
    desc = F.describe(images, "sad")
    curve, turn, same_way, _ = F.pair_curves(desc, "sad", positions, headings)
    d = F.differences(desc, desc, "sad")
    far = [d[i, j] for i in range(6) for j in range(i + 1, 6) if abs(positions[i, 0] - positions[j, 0]) > 100]
    assert len(far) == 11 and curve.far_median == pytest.approx(float(np.median(far)))
    assert curve.values[0] == 0.0 and curve.counts[0] == 2  # identical images 1 m apart
    assert curve.values[1] is None and curve.counts[1] == 0
    assert curve.values[2] == pytest.approx(d[0, 5] / curve.far_median)  # A vs A' 4 and 5 m apart
    assert curve.counts[2] == 2 and d[0, 5] > 0
    # pairs within 3 m: (0, 1) turned 100 degrees, (2, 3) not turned
    assert turn.counts == [1, 0, 0, 1, 0, 0] and turn.values[0] == turn.values[3] == 0.0
    # the same-way curve leaves out the turned pairs: (0, 1) at 1 m, and (1, 5) at 4 m
    assert same_way.counts[0] == 1 and same_way.counts[2] == 1
    assert same_way.values[2] == pytest.approx(d[0, 5] / curve.far_median)
    assert same_way.far_median == curve.far_median


def test_aliasing_counts_far_pairs_more_alike_than_the_street_ahead() -> None:
    """Far pairs below the median same-way difference at 10-12 m: here place A seen again
    200 m away, from both frames of its street; the unrelated places are not alike."""
    a, c = _image(1), _image(3)
    a2, c2 = a.copy(), c.copy()
    a2[10:20, 10:20] = 255  # the street 11 m on: a little changed
    c2[10:30, 10:30] = 255  # a little more
    images = np.stack([a, a2, a, c, c2])
    positions = np.array([[0, 0], [11, 0], [200, 0], [400, 0], [411, 0]], float)
    desc = F.describe(images, "sad")
    curves = F.pair_curves(desc, "sad", positions, np.zeros(5))
    far = [(i, j) for i in range(5) for j in range(i + 1, 5) if abs(positions[i, 0] - positions[j, 0]) > 100]
    d = F.differences(desc, desc, "sad")
    ref = np.median([d[0, 1], d[3, 4]])
    assert curves.alias_share == pytest.approx(np.mean([d[i, j] < ref for i, j in far]))
    assert len(far) == 8 and curves.alias_share == pytest.approx(2 / 8)  # (0, 2) and (1, 2)
    assert F.pair_curves(desc[:3:2], "sad", positions[:3:2], np.zeros(2)).alias_share is None


def test_route_measures_of_a_lap_and_of_a_long_loop() -> None:
    """A 400 m square driven twice at 10 m/s: every frame of the second lap revisits after a
    400 m loop (a short lap); a 1200 m square driven 1.5 times: loops of 1200 m, none short."""
    def square(side: float, laps: float) -> tuple[np.ndarray, np.ndarray]:
        s = np.arange(0.0, 4 * side * laps, 1.0)
        u = s % (4 * side)
        k, r = (u // side).astype(int), u % side
        corners = np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], float)
        xy = corners[k] + (corners[k + 1] - corners[k]) * (r / side)[:, None]
        return xy, s / 10.0

    xy, t = square(100.0, 2)
    lap = F.route_measures(xy, t)
    # the latest earlier pass within 5 m lies up to 5 m ahead of the frame: loops of 395-400 m
    assert lap.loop_min_m == pytest.approx(397, abs=5) and lap.loop_median_m == pytest.approx(397, abs=3)
    assert lap.revisit_share == pytest.approx(lap.short_lap_share) and 0.45 < lap.short_lap_share < 0.52
    assert lap.third_pass_share < 0.01 and lap.gap_median_s == pytest.approx(39.5, abs=0.3)
    xy, t = square(300.0, 1.5)
    loop = F.route_measures(xy, t)
    assert loop.short_lap_share == 0.0 and loop.loop_min_m == pytest.approx(1197, abs=5)
    xy, t = square(100.0, 3)
    assert F.route_measures(xy, t).third_pass_share > 0.3
    none = F.route_measures(np.stack([np.arange(50.0), np.zeros(50)], axis=1), np.arange(50.0))
    assert none.revisit_share == 0.0 and none.loop_min_m is None
    with pytest.raises(DataError, match="as many times as positions"):
        F.route_measures(np.zeros((3, 2)), np.zeros(2))


def test_polar_descriptor_is_rotation_invariant_and_sad_is_not() -> None:
    image = np.zeros((151, 151), np.uint8)
    image[20:30, 60:70] = 255
    image[90:95, 100:140] = 128
    pair = np.stack([image, np.rot90(image, -1)])  # the viewpoint turned left by 90 degrees
    polar = F.difference_matrix(pair, "polar")
    sad = F.difference_matrix(pair, "sad")
    assert polar[0, 1] < 0.05 and sad[0, 1] > 10 * polar[0, 1]
    assert F.polar_descriptors(pair).shape == (2, F.POLAR_RINGS, F.POLAR_SECTORS)


def test_envelope_excess() -> None:
    def curve(values: list[float | None]) -> F.Curve:
        return F.Curve([0.0, 2.0, 4.0, 6.0], values, [1] * len(values), 1.0)

    real = [curve([0.3, 0.6, 0.9]), curve([0.5, 0.8, None])]
    assert F.envelope_excess(curve([0.4, 0.7, 2.0]), real) == (0.0, None)  # inside; bin 2 not comparable
    value, where = F.envelope_excess(curve([0.65, 0.5, 0.9]), real)
    assert value == pytest.approx(0.15) and where == 0
    value, where = F.envelope_excess(curve([0.4, 1.0, 0.9]), real)
    assert value == pytest.approx(0.2) and where == 1


def test_goals_check_each_target() -> None:
    met = {g.name: g for g in F.goals(0.03, [0.063, 0.074], 0.058, 0.8)}
    assert all(g.met for g in met.values())
    assert met["nonzero_fraction"].target == "5.67-8.14 %"  # each end moved out by 10 % of it
    missed = {g.name: g.met for g in F.goals(0.031, [0.063, 0.074], 0.056, None)}
    assert missed == {"curve_envelope_excess": False, "nonzero_fraction": False, "ranking_tau": False}
    assert not {g.name: g.met for g in F.goals(0.0, [0.063, 0.074], 0.082, 1.0)}["nonzero_fraction"]


def _scored(m: str, t: str, skill: float, variant: int = 0, seed: int = 0) -> F.MethodResult:
    """A method's single-frame result on task `t` from per-query outcomes (`task_outcomes`: the
    methods of one task share its queries and true places; `seed` picks the task's queries)."""
    from record_factory import task_outcomes

    from safl_bench.metrics import evaluate_outcomes

    o = task_outcomes(seed, skill, variant)
    return F.MethodResult(m, t, None, evaluate_outcomes(o).f1_max, "record", outcomes=[o])


def test_tau_b_of_pair_orders_is_kendalls_tau_b_with_ties() -> None:
    from itertools import combinations

    from scipy.stats import kendalltau

    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.integers(0, 3, 7), rng.integers(0, 4, 7)
        pairs = list(combinations(range(7), 2))
        ox = [int(np.sign(x[i] - x[j])) for i, j in pairs]
        oy = [int(np.sign(y[i] - y[j])) for i, j in pairs]
        expected = kendalltau(x, y).statistic
        got = F._tau_b(ox, oy)
        assert (got is None) == (not np.isfinite(expected))
        if got is not None:
            assert got == pytest.approx(expected)


def test_ranking_tau_counts_unresolved_orders_as_ties() -> None:
    # S: strong > mid > weak, each resolved; R1: strong and mid of the same skill (other draws),
    # so their order is not beyond the noise whatever their F1max says: a tie on that side
    results = {
        "strong": {"S": _scored("strong", "S", 0.95), "R1": _scored("strong", "R1", 0.95, seed=1)},
        "mid": {"S": _scored("mid", "S", 0.6), "R1": _scored("mid", "R1", 0.95, variant=1, seed=1)},
        "weak": {"S": _scored("weak", "S", 0.2), "R1": _scored("weak", "R1", 0.2, seed=1)},
    }
    orders = {(o.first, o.second): o for o in F.pair_orders(results, "R1")}
    assert set(orders) == {("mid", "strong"), ("mid", "weak"), ("strong", "weak")}
    tied = orders["mid", "strong"]
    assert tied.order == 0 and tied.verdict == "tied" and not tied.difference.excludes_zero()
    assert tied.difference.mean != 0  # the means differ, the noise decides nothing
    assert orders["strong", "weak"].order == 1 and orders["mid", "weak"].verdict == "mid > weak resolved"
    s_orders = {(o.first, o.second): o.order for o in F.pair_orders(results, "S")}
    assert s_orders == {("mid", "strong"): -1, ("mid", "weak"): 1, ("strong", "weak"): 1}
    taus = F.ranking_tau(results, "S", ["R1"])
    # pairs (S, R1): (-1, 0), (1, 1), (1, 1): tau-b = 2 / sqrt(3 * 2)
    assert taus["R1"] == pytest.approx(2 / np.sqrt(6)) and taus["mean"] == pytest.approx(2 / np.sqrt(6))
    # a second real task that reverses mid and weak: across the real tasks that pair is a tie
    results["mid"]["R2"] = _scored("mid", "R2", 0.2, seed=2)
    results["weak"]["R2"] = _scored("weak", "R2", 0.6, seed=2)
    results["strong"]["R2"] = _scored("strong", "R2", 0.95, seed=2)
    taus = F.ranking_tau(results, "S", ["R1", "R2"])
    assert taus["mean"] == pytest.approx(1 / np.sqrt(3))  # only strong > weak agrees: 1 / sqrt(3 * 1)


def test_pairs_without_outcomes_are_ties_and_all_ties_give_no_tau() -> None:
    def bare(m: str, t: str, f1: float) -> F.MethodResult:
        return F.MethodResult(m, t, None, f1, "record")  # metrics version 1: no per-query outcomes

    results = {m: {t: bare(m, t, v) for t in ("S", "R1")} for m, v in (("a", 0.9), ("b", 0.5))}
    (order,) = F.pair_orders(results, "R1")
    assert order.order == 0 and order.difference is None
    assert F.ranking_tau(results, "S", ["R1"]) == {"R1": None, "mean": None}
    results["c"] = {"S": F.MethodResult("c", "S", None, None, "missing")}  # no value: left out
    assert [(o.first, o.second) for o in F.pair_orders(results, "S")] == [("a", "b")]


def test_fidelity_cli_needs_real_data(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, bev_root: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("SAFL_BEV_ROOT", raising=False)
    monkeypatch.setenv("SAFL_HOME", str(tmp_path / "home"))
    assert main(["data", "fidelity", "--out", str(tmp_path / "f.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--bev-root" in err and "SAFL_BEV_ROOT" in err
    assert main(["data", "fidelity", "--bev-root", str(tmp_path / "nowhere")]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert main(["data", "fidelity", "--bev-root", str(bev_root), "--sequences", "00", "02"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(bev_root / "02") in err and "00" in err
    assert not (tmp_path / "home").exists()  # nothing was generated before the check


def test_fidelity_cli_end_to_end_on_tiny_data(kitti_root: Path, safl_home: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    # the "real" side: the tiny KITTI sequence exported as BEVPlace's images; the "synthetic"
    # side: the same scans (--synth-root): every statistic agrees, the excess is 0
    real = tmp_path / "real"
    assert main(["data", "export", "--kitti-root", str(kitti_root), "--out", str(real), "--quiet"]) == 0
    out, js = tmp_path / "f.png", tmp_path / "f.json"
    argv = ["data", "fidelity", "--bev-root", str(real), "--sequences", "00", "--synth-root", str(kitti_root),
            "--out", str(out), "--json", str(js), "--quiet"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "non-zero pixels" in text and "place recognition skipped" in text and out.is_file()
    report = json.loads(js.read_text())
    nz = report["nonzero_fraction"]
    assert nz["real"]["00"] == pytest.approx(nz["synthetic"]) and nz["synthetic"] > 0
    assert report["curve_envelope_excess"] == 0.0 and report["ranking_tau"] is None
    assert report["same_way_envelope_excess"] == {"sad": 0.0, "polar": 0.0}
    goals = report["goals"]
    assert goals["curve_envelope_excess"]["met"] and goals["nonzero_fraction"]["met"]
    assert not goals["ranking_tau"]["met"]  # no place recognition, no tau
    assert "goals: curve_envelope_excess 0.000 (goal <= 0.03): met" in text


def test_place_recognition_reads_records_and_ranks(tmp_path: Path) -> None:
    from record_factory import make_record

    from safl_bench.records import write_record

    results, extra = tmp_path / "results", tmp_path / "committed"
    f1 = {"sad": (0.9, 0.8, 0.5), "bigan": (0.95, 0.9, 0.7), "stable_afl": (0.97, 0.85, 0.72)}
    for method, (s, r0, r2) in f1.items():
        write_record(extra, make_record(method, protocol="revisit", condition=None, f1=s, recall_at_1=0.5,
                                        task_version=4))
        for seq, v in (("00", r0), ("02", r2)):
            write_record(results, make_record(method, protocol="revisit", condition=None, sequence=seq,
                                              source_kind="bev", f1=v, recall_at_1=0.8))
    tasks = ["SAFL/BEVKITTI00-Revisit-v0", "SAFL/BEVKITTI02-Revisit-v0"]
    pr = F.place_recognition(["sad", "bigan@1", "stable_afl@1", "bevplace"], "SAFL/Synth00-Revisit-v4", tasks,
                             results_dir=results, extra_record_dirs=[extra], run=False)
    assert list(pr) == ["sad", "bigan@1", "stable_afl@1", "bevplace"]
    assert pr["sad"]["SAFL/BEVKITTI02-Revisit-v0"].f1_max == pytest.approx(0.25)  # single-frame: f1 * 0.5
    assert pr["bigan@1"]["SAFL/Synth00-Revisit-v4"].recall_at_1 == pytest.approx(0.25)  # its records
    assert pr["bevplace"]["SAFL/BEVKITTI00-Revisit-v0"].status == "missing"
    assert pr["bigan@1"]["SAFL/Synth00-Revisit-v4"].outcomes is None  # these records hold none
    taus = F.ranking_tau(pr, "SAFL/Synth00-Revisit-v4", tasks)
    assert taus == dict.fromkeys([*tasks, "mean"])  # no outcomes: no order beyond the noise


def test_mixed_weights_are_named() -> None:
    # a learned method run with one set of weights on the synthetic task and another on the real
    # tasks ranks two trainings, not only two data sets: the fidelity report says which
    w_syn = {"weights": {"path": "baselines/weights/bigan.safetensors", "sha256": "92061236b6c2" + "0" * 52}}
    w_bev = {"weights": {"path": "baselines/weights/bigan-bev.safetensors", "sha256": "5aae9d521a8f" + "0" * 52}}
    assert F.weights_label(w_syn) == "bigan.safetensors 92061236b6c2"
    assert F.weights_label({"params": {}}) == ""
    assert F.weights_label({"weights": {"source": "untrained"}}) == "untrained"

    def res(m: str, t: str, weights: dict, f1: float | None = 0.8) -> F.MethodResult:
        return F.MethodResult(m, t, None, f1, "record", weights=F.weights_label(weights))

    results = {
        "bigan": {"S": res("bigan", "S", w_syn), "R1": res("bigan", "R1", w_bev), "R2": res("bigan", "R2", w_bev)},
        "stable_afl": {t: res("stable_afl", t, w_syn) for t in ("S", "R1", "R2")},
        "sad": {t: res("sad", t, {}) for t in ("S", "R1", "R2")},
        "bevplace": {"S": res("bevplace", "S", w_syn), "R1": res("bevplace", "R1", w_bev, f1=None)},
    }
    mixed = F.mixed_weights(results)
    assert set(mixed) == {"bigan"}  # bevplace's other weights gave no result: nothing ranked with them
    assert mixed["bigan"] == {"S": "bigan.safetensors 92061236b6c2", "R1": "bigan-bev.safetensors 5aae9d521a8f",
                              "R2": "bigan-bev.safetensors 5aae9d521a8f"}


def test_the_report_prints_each_pairs_difference_interval_and_verdict() -> None:
    from safl_bench.cli.data_fidelity import _order_rows, _order_text

    results = {
        "strong": {"S": _scored("strong", "S", 0.95)},
        "weak": {"S": _scored("weak", "S", 0.2)},
        "bare": {"S": F.MethodResult("bare", "S", None, 0.5, "record")},
    }
    orders = {"S": F.pair_orders(results, "S"), "R": []}
    rows = _order_rows(orders, ["R", "S"])
    assert rows[0] == ["pair (first - second)", "R", "S"]
    by_pair = {r[0]: r[1:] for r in rows[1:]}
    (resolved,) = [o for o in orders["S"] if (o.first, o.second) == ("strong", "weak")]
    iv = resolved.difference
    assert by_pair["strong - weak"] == ["n/a", f"{iv.mean:.3f} [{iv.low:.3f}, {iv.high:.3f}] strong > weak"]
    assert by_pair["bare - strong"][1] == "n/a (no per-query outcomes) tied"
    assert _order_text(resolved).endswith("strong > weak")
