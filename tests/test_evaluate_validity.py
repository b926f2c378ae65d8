"""Score validity helpers: rank correlation, its bootstrap interval, candidate draws, poses."""

import numpy as np
import pytest

from scenebot.evaluate.metrics import EvaluationError
from scenebot.evaluate.validity import (
    _candidate_pose,
    bootstrap_interval,
    pick_candidates,
    spearman,
)


def test_spearman_is_a_rank_statistic():
    rng = np.random.default_rng(0)
    a = rng.normal(size=200)
    b = -2.0 * a + rng.normal(scale=0.5, size=200)
    rho = spearman(a, b)
    assert -1.0 <= rho < -0.8
    # any increasing transform of either variable leaves it unchanged
    assert spearman(np.exp(a), b**3) == pytest.approx(rho)
    assert spearman(a, -b) == pytest.approx(-rho)
    assert np.isnan(spearman(a[:2], b[:2]))
    assert np.isnan(spearman(np.ones(10), np.arange(10)))


def test_bootstrap_interval_brackets_the_estimate_and_shrinks_with_more_pairs():
    rng = np.random.default_rng(1)

    def sample(n):
        a = rng.normal(size=n)
        return a, a + rng.normal(scale=1.0, size=n)

    lo_s, hi_s = bootstrap_interval(*sample(30), seed=0)
    a, b = sample(600)
    lo, hi = bootstrap_interval(a, b, seed=0)
    assert lo <= spearman(a, b) <= hi
    assert hi - lo < hi_s - lo_s
    assert -1.0 <= lo_s <= hi_s <= 1.0


def test_pick_candidates_keeps_only_scored_views_that_hit_the_mesh():
    n = 50
    cands = {
        "score_deg": np.where(np.arange(n) % 5 == 0, np.nan, np.linspace(5, 120, n)),
        "hit_fraction": np.where(np.arange(n) % 7 == 0, 0.05, 0.9),
    }
    got = pick_candidates(cands, 20, 0.2, seed=3)
    assert len(got) == 20 == len(set(got.tolist()))
    assert np.all(np.isfinite(cands["score_deg"][got]))
    assert np.all(cands["hit_fraction"][got] >= 0.2)
    np.testing.assert_array_equal(got, pick_candidates(cands, 20, 0.2, seed=3))  # seeded
    assert len(pick_candidates(cands, 1000, 0.2, seed=3)) < n  # all usable ones, no more
    with pytest.raises(EvaluationError, match="n_candidates"):
        pick_candidates({k: v[:2] for k, v in cands.items()}, 10, 0.2, seed=0)


def test_candidate_pose_is_the_score_stage_camera():
    """Centre at (x, y, 0), looking along theta, image y axis down (world -z)."""
    R, t = _candidate_pose(1.5, -0.5, np.pi / 2)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(-R.T @ t, [1.5, -0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(R[2], [0.0, 1.0, 0.0], atol=1e-12)  # forward
    np.testing.assert_allclose(R[1], [0.0, 0.0, -1.0], atol=1e-12)  # down


def test_baseline_configs_keep_the_campaign_and_change_only_the_method():
    from scenebot.config import validate_config
    from scenebot.evaluate.baselines import baseline_config

    campaign = {"scene": "office", "max_rounds": 3, "exploration": {"photos": 100},
                "goals": {"k": 5}}  # fmt: skip
    rnd = baseline_config(campaign, "random", 140)
    assert rnd["max_rounds"] == 1 and rnd["exploration"]["photos"] == 140
    fr = baseline_config(campaign, "frontier", 140)
    assert fr["goals"] == {"k": 5, "method": "frontier"} and fr["max_rounds"] == 3
    # the adaptive campaign stopped by itself after 2 rounds: the frontier one runs as many
    assert baseline_config(campaign, "frontier", 140, rounds=2)["max_rounds"] == 2
    assert campaign["goals"] == {"k": 5}  # the campaign's own config is not touched
    for cfg in (rnd, fr):
        assert cfg["evaluate"]["validity_candidates"] == 0
        validate_config(cfg, "baseline")  # a valid campaign config
    with pytest.raises(ValueError, match="unknown baseline"):
        baseline_config(campaign, "oracle", 140)


def test_a_baseline_shares_the_campaigns_cache(tmp_path, monkeypatch):
    """The nested campaign runs in its own folder: a relative evaluate.cache_dir is made
    absolute (the same folder); unset or '' it stays as it is (the environment is
    inherited)."""
    from scenebot.evaluate.baselines import _nested_env, baseline_config

    monkeypatch.chdir(tmp_path)
    for method in ("random", "frontier"):
        cfg = baseline_config({"evaluate": {"cache_dir": "cache"}}, method, 50)
        assert cfg["evaluate"]["cache_dir"] == str(tmp_path / "cache")
        off = baseline_config({"evaluate": {"cache_dir": ""}}, method, 50)
        assert off["evaluate"]["cache_dir"] == ""
        assert "cache_dir" not in baseline_config({}, method, 50)["evaluate"]
    monkeypatch.setenv("SCENEBOT_CACHE", str(tmp_path / "env"))
    assert _nested_env(tmp_path / "Snakefile")["SCENEBOT_CACHE"] == str(tmp_path / "env")
