"""PPO with no reward must not move the policy: the zero-reward control, and the spatial policy's
distribution against hand computations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from sc2data.rl.envs import PAPER_FUNCTIONS
from sc2data.rl.spatial import POINT_FUNCTIONS, PaperPolicy, PointDistribution, _pointwise, sample
from sc2data.rl.train import RLConfig, make_vec_env, new_model, train

CONTROL = dict(action_space="paper", reward="zero", steps=2048, envs=8, rollout=64,
               batch_size=256, episode_steps=200, checkpoint_every=10**6, progress=False, seed=3,
               processes=0, threads=1)


def _policy_kl(run: Path, cfg: RLConfig) -> float:
    """Mean KL(initial ‖ trained) of the function head over states the initial policy visits."""
    from sb3_contrib import MaskablePPO

    vec = make_vec_env(cfg)
    try:
        first = new_model(cfg, vec, cfg.seed)
        trained = MaskablePPO.load(run / "model.zip", device="cpu")
        vec.seed(1234)
        obs = vec.reset()
        batches = []
        for _ in range(12):
            masks = vec.action_masks()
            batches.append(({k: v.copy() for k, v in obs.items()}, masks))
            acts, _ = first.predict(obs, action_masks=masks)
            obs, *_ = vec.step(acts)
    finally:
        vec.close()
    kls = []
    with torch.no_grad():
        for o, m in batches:
            t = first.policy.obs_to_tensor(o)[0]
            p = first.policy.get_distribution(t, m)
            q = trained.policy.get_distribution(t, m)
            lp = torch.log_softmax(p.function_logits, 1)
            lq = torch.log_softmax(q.function_logits, 1)
            kls.append(float((lp.exp() * (lp - lq)).sum(1).mean()))
    return float(np.mean(kls))


@pytest.mark.slow
def test_zero_reward_control_stays_at_the_initial_policy(tmp_path: Path) -> None:
    """With no reward, the defaults (advantages not normalised, an early stop at target_kl)
    leave the policy where it started; SB3's normalised advantages move it (the drift the
    control is there to catch: each update a full clipped step of noise). Averaged over three
    seeds: one run's KL varies tenfold with its random draws (still 0.0003–0.0035, moved
    0.002–0.05 over seeds 3–5)."""
    kls: dict[str, list[float]] = {"still": [], "moved": []}
    for seed in (3, 4, 5):
        for name, extra in (("still", {}), ("moved", {"normalize_advantage": True,
                                                     "target_kl": None})):
            cfg = RLConfig(out=str(tmp_path / f"{name}{seed}"),  # type: ignore[arg-type]
                           **{**CONTROL, "seed": seed, **extra})
            train(cfg)
            kls[name].append(_policy_kl(Path(cfg.out), cfg))
    kl_still, kl_moved = float(np.mean(kls["still"])), float(np.mean(kls["moved"]))
    assert kl_still < 0.005, kls
    assert kl_moved > 5 * kl_still, kls


def _dist(b: int = 2, side: int = 64) -> PointDistribution:
    g = torch.Generator().manual_seed(0)
    fn = torch.randn(b, len(PAPER_FUNCTIONS), generator=g)
    pts = torch.randn(b, len(POINT_FUNCTIONS), side * side, generator=g)
    return PointDistribution(fn, pts)


def test_point_log_prob_counts_the_point_only_for_functions_that_take_one() -> None:
    d = _dist()
    takes = PAPER_FUNCTIONS.index("Build_Barracks_screen")
    plain = PAPER_FUNCTIONS.index("Train_Marine_quick")
    acts = torch.tensor([[takes, 5, 7], [plain, 5, 7]])
    lp = d.log_prob(acts)
    lf = torch.log_softmax(d.function_logits, 1)
    slot = POINT_FUNCTIONS.index("Build_Barracks_screen")
    lpt = torch.log_softmax(d.point_logits[0, slot], 0)[7 * 64 + 5]
    assert torch.allclose(lp[0], lf[0, takes] + lpt)
    assert torch.allclose(lp[1], lf[1, plain])  # x and y ignored: no mass, no entropy
    other = d.log_prob(torch.tensor([[takes, 5, 7], [plain, 60, 1]]))
    assert torch.allclose(other[1], lp[1])


def test_a_cell_shares_its_probability_evenly_among_its_pixels() -> None:
    d = _dist(1, side=32)
    f = PAPER_FUNCTIONS.index("select_point")
    slot = POINT_FUNCTIONS.index("select_point")
    cell = torch.log_softmax(d.point_logits[0, slot], 0)[3 * 32 + 10]
    lf = torch.log_softmax(d.function_logits, 1)[0, f]
    for x, y in ((20, 6), (21, 6), (20, 7), (21, 7)):  # the four pixels of cell (10, 3)
        lp = d.log_prob(torch.tensor([[f, x, y]]))[0]
        assert torch.allclose(lp, lf + cell - np.log(4.0))
    total = torch.logsumexp(torch.stack([d.log_prob(torch.tensor([[f, x, y]]))[0]
                                         for x in range(64) for y in range(64)]), 0)
    assert torch.allclose(total, lf, atol=1e-5)  # the 4,096 pixels sum to π(f)
    for _ in range(10):
        a = d.get_actions()[0]
        assert 0 <= int(a[1]) < 64 and 0 <= int(a[2]) < 64


def test_the_pointwise_product_is_a_1x1_convolution_and_its_gradient() -> None:
    torch.manual_seed(0)
    layer = torch.nn.Linear(13, 5)
    x = torch.rand(3, 13, 8, 8)
    y = _pointwise(layer, x)
    ref = torch.nn.functional.conv2d(x, layer.weight[:, :, None, None], layer.bias)
    assert y.shape == (3, 5, 8, 8) and torch.allclose(y, ref, atol=1e-6)
    g = torch.rand_like(y)
    got = torch.autograd.grad(y, (layer.weight, layer.bias), g)
    want = torch.autograd.grad(ref, (layer.weight, layer.bias), g)
    assert all(torch.allclose(a, b, atol=1e-5) for a, b in zip(got, want))


def test_point_entropy_is_the_joint_entropy_by_hand() -> None:
    d = _dist(1)
    lf = torch.log_softmax(d.function_logits[0], 0)
    h = -(lf.exp() * lf).sum()
    for j, name in enumerate(POINT_FUNCTIONS):
        lq = torch.log_softmax(d.point_logits[0, j], 0)
        h = h + lf[PAPER_FUNCTIONS.index(name)].exp() * -(lq.exp() * lq).sum()
    assert torch.allclose(d.entropy()[0], h)


def test_masked_functions_get_no_mass_and_argmax_follows_the_maps() -> None:
    d = _dist(1)
    mask = np.zeros((1, len(PAPER_FUNCTIONS) + 128), bool)
    build = PAPER_FUNCTIONS.index("Build_SupplyDepot_screen")
    mask[0, build] = mask[0, PAPER_FUNCTIONS.index("no_op")] = True
    mask[0, len(PAPER_FUNCTIONS):] = True
    d.point_logits[0, POINT_FUNCTIONS.index("Build_SupplyDepot_screen")] = -5.0
    d.point_logits[0, POINT_FUNCTIONS.index("Build_SupplyDepot_screen"), 30 * 64 + 12] = 9.0
    d.function_logits[0, build] = 50.0
    d.apply_masking(mask)
    assert torch.equal(d.get_actions(deterministic=True)[0], torch.tensor([build, 12, 30]))
    for _ in range(20):
        assert int(d.get_actions()[0, 0]) in (build, PAPER_FUNCTIONS.index("no_op"))


def test_the_pixel_head_is_the_cell_head_plus_a_choice_within_the_cell(tmp_path: Path) -> None:
    """``--point-head pixel`` at a 32×32 observation: one logit per screen pixel; with its
    within-cell convolution and pixel preferences at zero (the preferences start so) it is the
    ``cell`` head of the same weights exactly (log probabilities, entropy); the convolution's
    bias alone moves the most likely point within the cell, a preference across cells."""
    base = dict(action_space="paper", envs=1, processes=0, episode_steps=30)
    runs = {}
    for head in ("cell", "pixel"):
        cfg = RLConfig(out=str(tmp_path / head), point_head=head, **base)  # type: ignore[arg-type]
        vec = make_vec_env(cfg)
        runs[head] = (new_model(cfg, vec, 0).policy, vec)
    cell, pixel = runs["cell"][0], runs["pixel"][0]
    try:
        assert pixel.within is not None and cell.within is None and cell.place is None
        assert pixel.place is not None and not pixel.place.any()  # the preferences start at 0
        state = {k: v for k, v in pixel.state_dict().items()
                 if not k.startswith(("within.", "place"))}
        cell.load_state_dict(state)
        with torch.no_grad():
            pixel.within.weight.zero_()
            pixel.within.bias.zero_()
        vec = runs["cell"][1]
        vec.seed(0)
        obs = cell.obs_to_tensor(vec.reset())[0]
        dc, dp = cell.get_distribution(obs), pixel.get_distribution(obs)
        assert dp.point_logits.shape[2] == 64 * 64 and dc.point_logits.shape[2] == 32 * 32
        f = PAPER_FUNCTIONS.index("Harvest_Gather_screen")
        acts = torch.tensor([[f, 10, 21], [f, 11, 21], [f, 63, 0],
                             [PAPER_FUNCTIONS.index("no_op"), 0, 0]])
        for a in acts:
            assert torch.allclose(dp.log_prob(a[None]), dc.log_prob(a[None]), atol=1e-5)
        assert torch.allclose(dp.entropy(), dc.entropy(), atol=1e-5)
        # A bias for the left column's lower pixel (dy 1, dx 0) of every Harvest cell.
        c2 = 4
        with torch.no_grad():
            pixel.within.bias[POINT_FUNCTIONS.index("Harvest_Gather_screen") * c2 + 2] = 5.0
            dp = pixel.get_distribution(obs)
            dp.function_logits[0, f] = 100.0
        _, x, y = (int(v) for v in dp.get_actions(deterministic=True)[0])
        assert x % 2 == 0 and y % 2 == 1
        best = int(dc.point_logits[0, POINT_FUNCTIONS.index("Harvest_Gather_screen")].argmax())
        assert (y // 2, x // 2) == divmod(best, 32)  # in the cell head's most likely cell
        for dx, dy in ((0, 0), (1, 0), (1, 1)):  # the cell's other three pixels: less likely
            other = dp.log_prob(torch.tensor([[f, x - x % 2 + dx, y - y % 2 + dy]]))
            assert float(other) < float(dp.log_prob(torch.tensor([[f, x, y]]))) - 4.0
        with torch.no_grad():  # a preference for pixel (45, 50): (dy 0, dx 1) of cell (22, 25)
            pixel.place[POINT_FUNCTIONS.index("Harvest_Gather_screen"), 1, 25 * 32 + 22] = 50.0
            dp = pixel.get_distribution(obs)
            dp.function_logits[0, f] = 100.0
        assert dp.get_actions(deterministic=True)[0].tolist() == [f, 45, 50]
        assert dp.get_actions()[0].tolist() == [f, 45, 50]  # sampled: the same layout read back
    finally:
        for _, v in runs.values():
            v.close()


@pytest.mark.parametrize("head", ["cell", "pixel"])
def test_the_spatial_policy_plays_masked_calls_only(tmp_path: Path, head: str) -> None:
    cfg = RLConfig(out=str(tmp_path / "r"), action_space="paper", envs=2, processes=0,
                   episode_steps=30, point_head=head)
    vec = make_vec_env(cfg)
    try:
        model = new_model(cfg, vec, 0)
        assert isinstance(model.policy, PaperPolicy)
        vec.seed(0)
        obs = vec.reset()
        for _ in range(40):
            masks = vec.action_masks()
            for deterministic in (True, False):
                acts, _ = model.predict(obs, deterministic=deterministic, action_masks=masks)
                assert all(masks[i, a[0]] for i, a in enumerate(acts))
            obs, _, _, infos = vec.step(acts)
            assert not any(i["invalid"] for i in infos)
    finally:
        vec.close()


def test_smdp_advantages_discount_each_decision_by_its_steps() -> None:
    """k = 1 everywhere: SB3's own GAE; k > 1: γ^k by hand."""
    from gymnasium import spaces
    from sb3_contrib.common.maskable.buffers import MaskableDictRolloutBuffer

    from sc2data.rl.smdp import SMDPRolloutBuffer

    obs = spaces.Dict({"v": spaces.Box(0, 1, (1,))})
    act = spaces.Discrete(2)
    rewards, values = [1.0, 0.0, 2.0], [0.5, 0.2, 0.1]
    bufs = []
    for cls in (SMDPRolloutBuffer, MaskableDictRolloutBuffer):
        b = cls(3, obs, act, gamma=0.9, gae_lambda=0.8, n_envs=1)
        for t in range(3):
            if isinstance(b, SMDPRolloutBuffer):
                b.record_steps([1])
            b.add({"v": np.zeros((1, 1))}, np.zeros((1, 1)), np.array([rewards[t]]),
                  np.array([t == 0]), torch.tensor([values[t]]), torch.zeros(1),
                  action_masks=np.ones((1, 2)))
        b.compute_returns_and_advantage(torch.tensor([0.3]), np.array([False]))
        bufs.append(b)
    assert np.allclose(bufs[0].advantages, bufs[1].advantages)

    b = SMDPRolloutBuffer(2, obs, act, gamma=0.9, gae_lambda=0.8, n_envs=1)
    for t, k in enumerate((5, 2)):
        b.record_steps([k])
        b.add({"v": np.zeros((1, 1))}, np.zeros((1, 1)), np.array([rewards[t]]),
              np.array([t == 0]), torch.tensor([values[t]]), torch.zeros(1),
              action_masks=np.ones((1, 2)))
    b.compute_returns_and_advantage(torch.tensor([0.3]), np.array([False]))
    d1 = rewards[1] + 0.9 ** 2 * 0.3 - values[1]
    d0 = rewards[0] + 0.9 ** 5 * values[1] - values[0]
    assert np.allclose(b.advantages[:, 0], [d0 + 0.9 ** 5 * 0.8 * d1, d1])


def test_potential_shaping_discounts_a_macro_decision_by_gamma_to_its_steps() -> None:
    """With SMDP discounting the shaping must be γᵏ·Φ(s') − Φ(s) to stay potential-based."""
    from sc2data.rl.batched import potential_step

    got = potential_step(np.array([1.0, 1.0]), np.array([2.0, 2.0]), np.array([False, True]),
                         0.9, np.array([3, 3]))
    assert np.allclose(got, [0.9 ** 3 * 2.0 - 1.0, -1.0])
    assert np.allclose(potential_step(np.array([1.0]), np.array([2.0]), np.array([False]), 0.9),
                       [0.9 * 2.0 - 1.0])


def test_the_sampler_draws_each_entry_as_often_as_its_probability() -> None:
    """Inverse-CDF sampling: frequencies within 4 standard errors of the softmax over 40,000
    draws a row, and never an entry of probability 0 (masked) — first, last or between."""
    torch.manual_seed(0)
    logits = torch.tensor([[-1e8, 0.0, 1.0, -1e8, 2.0, -1e8],
                           [3.0, -1e8, 0.5, 0.5, -1e8, -1.0]])
    p = torch.softmax(logits, 1)
    draws = sample(logits.repeat(40_000, 1)).view(40_000, 2)  # (draws, rows)
    for row in range(2):
        freq = torch.bincount(draws[:, row], minlength=6).double() / len(draws)
        assert (freq[p[row] == 0] == 0).all()
        se = torch.sqrt(p[row].double() * (1 - p[row].double()) / len(draws))
        assert ((freq - p[row].double()).abs() <= 4 * se + 1e-12).all(), (row, freq, p[row])
