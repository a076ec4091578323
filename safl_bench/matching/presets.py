"""Named matcher presets: whole sets of the shared matcher's settings, each with its source.

``safl-bench run --matcher-preset NAME`` picks one (default ``paper``), ``--matcher KEY=VALUE``
refines it, and ``safl-bench list matchers`` prints them all. A preset is an
`EvaluationConfig`: the sequence matcher's `MatcherConfig` (whose ``preset`` field carries the
name into every record) and the evaluation-level settings. Every record holds all of the
settings; `label` names them for tables ("paper", "authors+enhance_window=0").

``paper`` - the paper as printed: Table I (d_s = 10; V from 0.8 to 1.1 by 0.1) and Eq. 5-7
(`safl_bench.matching.matcher`, whose docstring says how each gap is filled), with Eq. 5's
window, which the paper does not give, chosen per cell by the ``dip`` rule: from the width of
the dip in the database's own self-difference, no ground truth and no score involved
(`safl_bench.matching.window` argues the rule and its constants). The default.

``paper-r10`` - what ``paper`` was before the rule (records made as ``paper`` until then are read
as this one: `MatcherConfig.from_dict`): the same, with OpenSeqSLAM's fixed window of 10
frames, centred. On these tasks (every 4th frame, 3.5 m apart; top views 60-80 m wide) those
+-5 frames lie inside the true match's own dip, and the enhancement ranks the true frame below
its neighbours (the matching.window docstring gives the numbers). These are the
`MatcherConfig` defaults, unchanged since before the presets.

``authors`` - the paper-era evaluation of the LEARNED features in the authors' public code,
repository CNN-GAN/Top-Mapping at commit ``25be0fd`` (2017-10-17, the last commit before the
December 2017 rewrite; src/plot/plotPaper2.py there names the Stable-AFL run behind the paper's
figures, ``r14_Cout_0.1_X_LS``, line 20), read for this (not copied). The scoring script is
src/plot/SLFL/plotDraw_slfl.py (src/plot/ULFL/plotDraw_2d.py does the same for the other
networks); its matcher is ``enhanceContrast`` and ``getMatches`` in src/util/utils.py; its
flags are those of parameters.py. Setting by setting (file:line@25be0fd; `CITATIONS` holds
them all, and `safl-bench list matchers` prints them):

- ``distance="euclidean"``: ``D = Euclidean(train_img, test_img)`` (plotDraw_slfl.py:62),
  ``np.linalg.norm(train[x]-test[y])`` (utils.py:76): the plain L2 norm, not Eq. 4's square.
  Contrast enhancement is not invariant to squaring, so this changes the matches.
- ``enhance_window=30``, centred: ``DD = enhanceContrast(D, 30)`` (plotDraw_slfl.py:63,
  plotDraw_2d.py:55; parameters.py:10's ``enhance`` = 20 is read by neither); the window is the
  rows ``i - enhance/2 .. i + enhance/2`` of the database axis, clipped, ``std(ddof=1)``
  (utils.py:198-202) - ``enhance_mode="centred"`` here.
- ``shift=False`` (QUIRK): ``#return DD-np.min(np.min(DD))`` is commented out (utils.py:204-205),
  so S is negative for good matches.
- ``ds=10``, velocities ``v_min=0.8 .. v_max=1.2`` by 0.1, inclusive (five): parameters.py:58
  ``v_ds`` = 10, :60 ``vmin`` = 0.8, :62 ``vmax`` = 1.2; ``arange(int(vmin*v_ds),
  int(vmax*v_ds)+1) / v_ds`` (utils.py:224-228; the ``vskip`` flag, parameters.py:61, is unused).
- ``trajectory="centred"``: ``n_start = N + 1 - v_ds/2`` over ``v_ds + 1`` queries, 1-based
  (utils.py:234-235).
- ``offset_rounding="floor_start"``: the k-th point at database row ``s + floor(k v)``
  (utils.py:230-231, 248), the match reported at ``min_idx + v_ds/2`` whatever v (utils.py:265).
- ``edge_queries="skip"``: ``for N in range(v_ds/2, DD.shape[1]-v_ds/2)`` (utils.py:216).
- ``out_of_range="exclude"``: a row of +inf is appended and indices past it clipped onto it
  (utils.py:241, 249). (The row is appended once per query, so the matrix grows; every added
  row is +inf, which changes nothing.)
- ``score="inverse"`` (QUIRK): ``match = [min_idx + v_ds/2, 1. / min_value]``, ``min_value``
  the trajectory SUM (utils.py:251-265); with unshifted z-scores a strong match has S < 0, so
  1/S ranks it below every positive S.
- ``capped_match=1`` (QUIRK): ``if match[1] > 1: match = 1.0`` sets BOTH columns to 1.0
  (utils.py:266-267): a query with 0 <= S < 1 reports database frame 1 at confidence 1.
- ``ratio_window=10``: parameters.py:63 ``Rwindow`` = 10 (utils.py:260-262 compute the second
  best S, which the commented-out ratio, utils.py:264, would use); unused by "inverse".
- ``trim_queries=5`` (evaluation level): ``match_PR = match[int(args.v_ds/2) :
  int(match.shape[0]-args.v_ds/2), :]`` (plotDraw_slfl.py:111, plotDraw_2d.py:79): v_ds/2 = 5
  queries dropped at each end, exactly those ``edge_queries="skip"`` leaves unanswered.
- ``max_frames=300`` (evaluation level): parameters.py:66 ``test_len`` = 300 with :64
  ``frame_skip`` = 1; the poses are read as ``[0 : test_len*frame_skip : frame_skip]``
  (plotDraw_slfl.py:51, 60), the descriptors saved for the same frames. GAP: their frames are
  the first 300 files of their ``new_loam/00`` folders (plotDraw_slfl.py:27, 46); whether those
  hold every KITTI frame or every 4th is not in the code. Here they are the first 300 task frames
  (the ``bev-paper`` tasks take every 4th KITTI frame).

The authors' PR reading (``recall[first precision >= 0.99]``, plotPaper2.py:59-60, over the
correctly matched queries) is a measure, not a setting: records carry it as
``authors_recall_at_99p`` (`safl_bench.evaluation.metrics`) beside ours.

``authors-sad`` - the authors' SAD (SeqSLAM) path at the same commit: src/third_function/
pyseqslam/seq_lidar.py drives ``SeqSLAM`` in src/third_function/pyseqslam/src/seqslam.py with
``defaultParameters`` of src/third_function/pyseqslam/src/parameters.py (pyseqslam/... below).
Every setting as ``authors`` except: ``ds=40`` (``getMatches_new``: ``v_ds = 40``,
seqslam.py:205, called at :197; v 0.8-1.2 at :206-207); ``enhance_window=10`` (parameters.py:44
``contrastEnhancement.R`` = 10; window seqslam.py:175-178); ``shift=True`` (``return
DD-np.min(np.min(DD))``, seqslam.py:180: S >= 0, so 1/S ranks strong matches first and caps
them at 1 only when S < 1); ``trim_queries=20`` (``results.matches[(int(args.v_ds)+10) : n -
args.v_ds - 10]`` with the top-level v_ds = 10, seq_lidar.py:116 - the same 20 queries that
ds = 40's ``skip`` leaves unanswered); ``distance="method"``: SAD's own sum of absolute
differences (seqslam.py:152-153, divided by the number of frames there, by the number of pixels
in `baselines.sad`: a constant factor, which the z-scores remove). What the matcher cannot
express, since it belongs to the image side: the preprocessing (seqslam.py:90-116): Lanczos
resize to 64 x 64 (parameters.py:21-23), grey (:97-99), 8-pixel patches normalised by their
z-score with ddof=1, ROUNDED to integers plus 127 and stored as uint8 (seqslam.py:137, 116;
parameters.py:27-28). ``--method sad --param size=64 --param normalisation=zscore`` comes close
(no rounding). GAP: seq_lidar.py:21 lists T1-T10 only: the T20 cells of Table II's SAD row are
not made by this script at this commit.

``authors-2018`` - the settings ``authors`` held before it took the paper-era values: the
repository's later state (commit ``9782be3``, 2018-03-17, its newest; parameters.py last changed
at ``f31182b``). As ``authors`` except: ``distance="method"`` (Eq. 4's square, where the code
still uses the L2 norm, src/util/utils.py:76@9782be3: this preset never followed it there);
``enhance_window=20`` (parameters.py:13@9782be3 ``enhance`` = 20 passed to ``enhanceContrast``,
utils.py:215@9782be3); ``trim_queries=20`` (``(v_ds + 10)`` queries, src/third_function/
pyseqslam/seq_lidar.py:116@9782be3, the SAD script's trim, which the learned features'
scripts do not use); ``max_frames=200`` (parameters.py:92@9782be3 ``test_len`` = 200 with :90
``frame_skip`` = 4: every 4th frame, as the tasks take them). Records made under the name
``authors`` before the rename hold these settings and are read as ``authors-2018``
(`safl_bench.evaluation.cell.RENAMED_PRESETS`).

Not part of any preset: ``dtype`` stays float32 (theirs is numpy's float64; ``--matcher
dtype=float64`` for their arithmetic); a window with zero spread divides by zero there (0 here).

``openseqslam`` - Milford & Wyeth's SeqSLAM as released in OpenSeqSLAM (Sünderhauf's MATLAB:
``findSingleMatch`` in doFindMatches.m; its defaults and contrast enhancement as in the Python
port the authors ship, src/third_function/pyseqslam/src/parameters.py ``defaultParameters`` and
seqslam.py ``SeqSLAM.enhanceContrast``): ``ds = 10``; velocities ``move_min:move_max`` over ds,
inclusive, with vmin 0.8 and vmax 1.2 (five); contrast enhancement over ``R = 10`` database
frames, centred, then shifted so that its minimum is 0; the trajectory centred on the query
(``n_start = N - ds/2``), anchored at its start with ``floor(k v)``, the match reported at
start + ds/2; no match for the first and last ds/2 queries; +inf past the database; the score
is the best S over the best S farther than ``Rwindow/2 = 5`` frames from the match
(``min_value / min_value_2nd``; MATLAB's window is inclusive, the port's drops one frame).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
from dataclasses import dataclass
from typing import Any

from safl_bench.errors import ConfigError
from safl_bench.matching.matcher import MatcherConfig
from safl_bench.matching.settings import EVALUATION_SETTINGS, EvaluationConfig

#: The preset a run uses when none is named.
DEFAULT = "paper"


@dataclass(frozen=True)
class Preset:
    """A named set of matcher settings, the one line that says where it comes from, and where
    each setting's value comes from (`citations`: setting -> file:line@commit or paper part)."""

    name: str
    description: str
    config: EvaluationConfig
    citations: dict[str, str]


def _preset(name: str, description: str, citations: dict[str, str], max_frames: int | None = None,
            trim_queries: int = 0, distance: str = "method", **matcher: Any) -> Preset:
    return Preset(name, description, EvaluationConfig(MatcherConfig(preset=name, **matcher),
                                                      max_frames=max_frames,
                                                      trim_queries=trim_queries,
                                                      distance=distance),
                  {"truth_at": _TRUTH_AT, "candidates": _CANDIDATES, "index": _CANDIDATES,
                   **citations})


#: No preset searches through candidates: the paper, the authors' code and OpenSeqSLAM all
#: match against every database frame.
_CANDIDATES = ("none of the paper, the authors' code and OpenSeqSLAM prunes candidates: every "
               "database frame (the exact matcher); candidates=K is this project's opt-in "
               "(safl_bench/matching/candidates.py)")

#: Every preset measures true places from the frame's pose: the paper does not say, and the
#: authors' scoring reads the test folder's own pose.txt (plotDraw_slfl.py:58-60, 113-117 at
#: 25be0fd), written by a data generator that is not in their repository.
_TRUTH_AT = ("paper §IV and the authors' code leave it open: their score reads the test "
             "folder's pose.txt (src/plot/SLFL/plotDraw_slfl.py:58-60, 113-117@25be0fd), whose "
             "generator is not in the repository; the frame's pose")


_TM = "CNN-GAN/Top-Mapping "
_MATCHING = "safl_bench/matching.py docstring (a gap the paper leaves, filled there)"

#: Where the ``paper-r10`` preset's values come from (the paper, Table I, Eq. 4-7).
_PAPER_R10 = {
    "ds": "paper Table I (d_s = 10)", "v_min": "paper Table I (V_min = 0.8)",
    "v_max": "paper Table I (V_max = 1.1)", "v_step": "paper Table I (V_step = 0.1)",
    "v_inclusive": "paper Table I (0.8 to 1.1)", "enhance_window": _MATCHING + ": OpenSeqSLAM's R = 10",
    "enhance_mode": _MATCHING, "trajectory": "paper Eq. 6 (the last d_s frames)",
    "edge_queries": _MATCHING, "out_of_range": _MATCHING, "score": "paper Eq. 7 (min S)",
    "ratio_window": _MATCHING + " (unused by min)", "dtype": "this project (float32)",
    "shift": _MATCHING, "offset_rounding": _MATCHING, "capped_match": "unused by min",
    "max_frames": "paper §IV (the whole test sequence)", "trim_queries": "paper (none)",
    "distance": "paper Eq. 4 (the method's difference: squared L2 for latent codes)",
    "enhance_rule": "this project (a fixed window)",
}
#: ``paper``: as ``paper-r10``, with the window from the data (`safl_bench.matching.window`).
_PAPER = {
    **_PAPER_R10,
    "enhance_window": "unused: the dip rule chooses it per cell",
    "enhance_rule": "safl_bench/matching/window.py docstring (the paper gives no window: from "
                    "the width of the database's self-difference dip)",
}

_U, _P, _S, _Q = ("src/util/utils.py:", "parameters.py:", "src/plot/SLFL/plotDraw_slfl.py:",
                  "src/third_function/pyseqslam/")
#: The paper-era learned-feature evaluation (``authors``), file:line at commit 25be0fd.
_AUTHORS = {
    "ds": _P + "58@25be0fd (v_ds = 10)", "v_min": _P + "60@25be0fd (vmin = 0.8)",
    "v_max": _P + "62@25be0fd (vmax = 1.2)", "v_step": _U + "224-228@25be0fd (moves of 1/v_ds)",
    "v_inclusive": _U + "227@25be0fd (int(move_max)+1)",
    "enhance_window": _S + "63@25be0fd (enhanceContrast(D, 30))",
    "enhance_mode": _U + "198-199@25be0fd (i-enhance/2 .. i+enhance/2)",
    "trajectory": _U + "234-235@25be0fd (n_start = N + 1 - v_ds/2)",
    "edge_queries": _U + "216@25be0fd (range(v_ds/2, n - v_ds/2))",
    "out_of_range": _U + "241, 249@25be0fd (+inf row, y[y>y_max]=y_max)",
    "score": _U + "265@25be0fd (1. / min_value)",
    "ratio_window": _P + "63@25be0fd (Rwindow = 10; unused)",
    "dtype": "this project (float32; theirs numpy float64)",
    "shift": _U + "204-205@25be0fd (the shift commented out)",
    "offset_rounding": _U + "230-231, 265@25be0fd (floor(k v); min_idx + v_ds/2)",
    "capped_match": _U + "266-267@25be0fd (match = 1.0)",
    "max_frames": _P + "66@25be0fd (test_len = 300; frame_skip = 1 at :64), " + _S + "51, 60",
    "trim_queries": _S + "111@25be0fd (match[v_ds/2 : n - v_ds/2])",
    "distance": _U + "76@25be0fd (np.linalg.norm), called at " + _S + "62",
    "enhance_rule": "a fixed window: " + _S + "63@25be0fd (enhanceContrast(D, 30))",
}

#: The authors' SAD path (``authors-sad``), where it differs from ``authors``, at 25be0fd.
_AUTHORS_SAD = {
    **_AUTHORS,
    "ds": _Q + "src/seqslam.py:205@25be0fd (getMatches_new: v_ds = 40)",
    "v_min": _Q + "src/seqslam.py:207@25be0fd (vmin = 0.8)",
    "v_max": _Q + "src/seqslam.py:206@25be0fd (vmax = 1.2)",
    "v_step": _Q + "src/seqslam.py:219-223@25be0fd", "v_inclusive": _Q + "src/seqslam.py:222@25be0fd",
    "enhance_window": _Q + "src/parameters.py:44@25be0fd (contrastEnhancement.R = 10)",
    "enhance_mode": _Q + "src/seqslam.py:175-176@25be0fd",
    "trajectory": _Q + "src/seqslam.py:229-230@25be0fd",
    "edge_queries": _Q + "src/seqslam.py:211@25be0fd",
    "out_of_range": _Q + "src/seqslam.py:236, 244@25be0fd",
    "score": _Q + "src/seqslam.py:260@25be0fd (1. / min_value)",
    "ratio_window": _Q + "src/seqslam.py:208@25be0fd (Rwindow = 10; unused)",
    "shift": _Q + "src/seqslam.py:180@25be0fd (DD - min(DD))",
    "offset_rounding": _Q + "src/seqslam.py:225-226, 260@25be0fd",
    "capped_match": _Q + "src/seqslam.py:261-262@25be0fd (match = 1.0)",
    "max_frames": _Q + "src/seqslam.py:73@25be0fd with " + _P + "66 (test_len = 300)",
    "trim_queries": _Q + "seq_lidar.py:116@25be0fd (v_ds + 10 = 20 at each end)",
    "distance": _Q + "src/seqslam.py:152-153@25be0fd (sum |d| / n: SAD, the method's own)",
    "enhance_rule": "a fixed window: " + _Q + "src/parameters.py:44@25be0fd (R = 10)",
}

#: ``authors-2018``: the settings "authors" held before the rename (the later code, 9782be3).
_AUTHORS_2018 = {
    **{k: v.replace("@25be0fd", "@25be0fd (unchanged at 9782be3)") for k, v in _AUTHORS.items()},
    "enhance_window": _P + "13@9782be3 (enhance = 20), passed to " + _U + "215@9782be3",
    "enhance_rule": "a fixed window: " + _P + "13@9782be3 (enhance = 20)",
    "max_frames": _P + "92@9782be3 (test_len = 200; frame_skip = 4 at :90)",
    "trim_queries": _Q + "seq_lidar.py:116@9782be3 (v_ds + 10: the SAD script's trim)",
    "distance": "this project's Eq. 4 square (the code's Euclidean, " + _U + "76@9782be3, is L2)",
}

_SQ = _Q + "src/"
#: ``openseqslam``: OpenSeqSLAM's defaults as the authors' Python port ships them (25be0fd).
_OPENSEQSLAM = {
    **_PAPER_R10,
    "ds": _SQ + "parameters.py:33@25be0fd (matching.ds = 10)",
    "v_max": _SQ + "parameters.py:37@25be0fd (vmax = 1.2)",
    "v_min": _SQ + "parameters.py:35@25be0fd (vmin = 0.8)",
    "v_step": _SQ + "seqslam.py:281-285@25be0fd", "v_inclusive": _SQ + "seqslam.py:284@25be0fd",
    "enhance_window": _SQ + "parameters.py:44@25be0fd (R = 10)",
    "enhance_mode": _SQ + "seqslam.py:175-176@25be0fd",
    "trajectory": _SQ + "seqslam.py:291-292@25be0fd", "edge_queries": _SQ + "seqslam.py:273@25be0fd",
    "offset_rounding": _SQ + "seqslam.py:287-288@25be0fd",
    "score": "OpenSeqSLAM doFindMatches.m findSingleMatch (min / min outside the window); the "
             "port's commented line " + _SQ + "seqslam.py:259@25be0fd",
    "ratio_window": _SQ + "parameters.py:38@25be0fd (Rwindow = 10)",
    "shift": _SQ + "seqslam.py:180@25be0fd",
    "enhance_rule": "a fixed window: " + _SQ + "parameters.py:44@25be0fd (R = 10)",
}


PRESETS: dict[str, Preset] = {p.name: p for p in (
    _preset("paper", "the paper: Table I and Eq. 5-7 as printed, Eq. 5's window (which the "
                     "paper does not give) from the database's self-difference dip; the default",
            _PAPER, enhance_rule="dip", enhance_window=0),
    _preset("paper-r10", "'paper' before the window rule: OpenSeqSLAM's fixed 10-frame "
                         "enhancement window (records made as 'paper' until then)", _PAPER_R10),
    _preset("authors", "the paper-era evaluation of learned features in the authors' code "
                       "(CNN-GAN/Top-Mapping@25be0fd plotDraw_slfl.py, utils.py, parameters.py): "
                       "plain L2, 30-frame unshifted z-scores, 1/S capped at 1, 300 frames",
            _AUTHORS, enhance_window=30, shift=False, v_max=1.2, trajectory="centred",
            offset_rounding="floor_start", edge_queries="skip", score="inverse",
            capped_match=1, max_frames=300, trim_queries=5, distance="euclidean"),
    _preset("authors-sad", "the authors' SAD path at the same commit (pyseqslam seqslam.py, "
                           "seq_lidar.py): ds 40, shifted 10-frame z-scores, 1/S capped at 1, "
                           "20 queries trimmed; its image preprocessing is the method's",
            _AUTHORS_SAD, ds=40, enhance_window=10, shift=True, v_max=1.2, trajectory="centred",
            offset_rounding="floor_start", edge_queries="skip", score="inverse",
            capped_match=1, max_frames=300, trim_queries=20),
    _preset("authors-2018", "what 'authors' was before: the authors' later code "
                            "(CNN-GAN/Top-Mapping@9782be3 parameters.py, utils.py, seq_lidar.py) "
                            "with Eq. 4's squared distance; records made as 'authors' then",
            _AUTHORS_2018, enhance_window=20, shift=False, v_max=1.2, trajectory="centred",
            offset_rounding="floor_start", edge_queries="skip", score="inverse",
            capped_match=1, max_frames=200, trim_queries=20),
    _preset("openseqslam", "Milford & Wyeth's SeqSLAM as released in OpenSeqSLAM: ratio to the "
                           "best S outside 10 frames, centred trajectory, V 0.8-1.2",
            _OPENSEQSLAM, v_max=1.2, trajectory="centred", offset_rounding="floor_start",
            edge_queries="skip", score="ratio"),
)}


def default_config() -> EvaluationConfig:
    """The settings of the default preset (`DEFAULT`), what a run without a preset uses."""
    return PRESETS[DEFAULT].config


def names() -> list[str]:
    """The presets' names, the default first."""
    return list(PRESETS)


def get(name: str) -> Preset:
    """The preset called `name`; ConfigError with "did you mean" and the list otherwise."""
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        close = difflib.get_close_matches(str(name), PRESETS, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ConfigError(f"unknown matcher preset {name!r}; {hint}presets: "
                          f"{', '.join(PRESETS)} (safl-bench list matchers)") from None


def citation(preset: Preset, setting: str) -> str:
    """Where `preset`'s value of `setting` comes from (file:line@commit, or the paper)."""
    return preset.citations.get(setting, "")


#: Settings `configure` (``--matcher KEY=VALUE``) may change, in the order tables list them.
SETTINGS: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(MatcherConfig) if f.name not in ("method", "preset")
) + EVALUATION_SETTINGS


#: One line per setting, for `safl-bench list matchers` (the module docstrings say more).
SETTING_HELP: dict[str, str] = {
    "ds": "trajectory length: ds + 1 queries (Table I d_s)",
    "v_min": "slowest trajectory velocity (Table I V_min)",
    "v_max": "fastest trajectory velocity (Table I V_max)",
    "v_step": "velocity step (Table I V_step)",
    "v_inclusive": "whether v_max itself is one of the velocities",
    "enhance_window": "contrast-enhancement window in database frames (Eq. 5; 0: off)",
    "enhance_mode": "that window centred on the frame, or ending at it (causal)",
    "enhance_rule": "the window as given (fixed), or from the database's self-difference dip (dip)",
    "trajectory": "trajectory ending at the query (causal, Eq. 6) or centred on it",
    "edge_queries": "queries without a full trajectory: a shorter one, or no match (skip)",
    "out_of_range": "trajectory points past the database: drop the candidate, or clip",
    "score": "query score: lowest S (min), S over the best S elsewhere (ratio), capped 1/S",
    "ratio_window": "frames around the match that the ratio's second best S may not use",
    "dtype": "arithmetic of the enhancement and the search",
    "shift": "shift the enhanced matrix so that its minimum is 0",
    "offset_rounding": "trajectory points: V u rounded about the query, or floor(V k) from its start",
    "capped_match": "inverse score: the frame reported when 1/S is capped (null: the match)",
    "max_frames": "only the first N task frames, database and queries (null: all)",
    "trim_queries": "queries left out of the metrics at each end of the sequence",
    "distance": "descriptor difference: the method's own (method) or plain L2 (euclidean)",
    "truth_at": "true places within the radius of the query frame's pose, or of its noisy viewpoint",
    "candidates": "search sequences through each query's K nearest frames only (null: exact)",
    "index": "the candidates' index: exact nearest frames (flat) or FAISS's IVF (ivf)",
}


def configure(name: str = DEFAULT, changes: dict[str, Any] | None = None,
              *, flag: str = "--matcher") -> EvaluationConfig:
    """Preset `name` with `changes` (setting -> value) on top; the name stays recorded as the
    ``preset`` setting, the changed values beside it. Giving ``enhance_window`` without
    ``enhance_rule`` means that fixed window (so ``enhance_window=0`` turns enhancement off on
    the ``paper`` preset too, whose rule would otherwise choose one). An unknown setting is a ConfigError that
    names the valid ones (`flag` names the option in the message)."""
    base = get(name).config
    changes = dict(changes or {})
    unknown = sorted(set(changes) - set(SETTINGS))
    if unknown:
        raise ConfigError(f"{flag}: unknown setting(s) {unknown}; valid: {sorted(SETTINGS)}")
    if "enhance_window" in changes and "enhance_rule" not in changes:
        changes["enhance_rule"] = "fixed"  # a window given is a fixed window (0: off)
    matcher = {k: v for k, v in changes.items() if k not in EVALUATION_SETTINGS}
    evaluation = {k: v for k, v in changes.items() if k in EVALUATION_SETTINGS}
    try:
        sequence = dataclasses.replace(base.sequence, **matcher)
    except TypeError as exc:  # a value of a type the dataclass cannot take
        raise ConfigError(f"{flag}: {exc}") from None
    return dataclasses.replace(base, sequence=sequence, **evaluation)


def settings(config: EvaluationConfig) -> dict[str, Any]:
    """Every setting of `config` by name (`SETTINGS`, then ``preset``), flat."""
    out = {name: getattr(config.sequence, name) for name in SETTINGS
           if name not in EVALUATION_SETTINGS}
    out.update({name: getattr(config, name) for name in EVALUATION_SETTINGS})
    out["preset"] = config.sequence.preset
    return out


def format_value(value: Any) -> str:
    """A setting's value as the command line takes it (``--matcher KEY=VALUE``)."""
    return value if isinstance(value, str) else json.dumps(value)


def changes(config: EvaluationConfig) -> dict[str, Any]:
    """The settings in which `config` differs from the preset it names ({} for an unknown
    preset name, e.g. one from a newer version)."""
    preset = PRESETS.get(config.sequence.preset)
    if preset is None:
        return {}
    mine, base = settings(config), settings(preset.config)
    diff = {k: v for k, v in mine.items() if k != "preset" and v != base[k]}
    if "enhance_rule" in diff and mine["enhance_rule"] == "fixed":
        diff["enhance_window"] = mine["enhance_window"]  # a fixed window: name it, 0 included
    return diff


def label(config: EvaluationConfig | dict[str, Any]) -> str:
    """How tables name a record's matcher settings: the preset, then what was changed on top,
    e.g. "paper", "paper+enhance_window=0", "authors+ds=5,score=min". Takes a config or a
    record's ``matcher`` field; a record made before the presets is "paper"; a field that
    cannot be read is "unreadable". Never raises."""
    if not isinstance(config, EvaluationConfig):
        try:
            config = EvaluationConfig.from_dict(config)
        except (ConfigError, TypeError):
            return "unreadable"
    diff = changes(config)
    name = config.sequence.preset
    if not diff:
        return name
    return name + "+" + ",".join(f"{k}={format_value(v)}" for k, v in diff.items())
