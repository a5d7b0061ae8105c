"""The MEM: inputs derived from the schema, encodings, the penalty, checkpoints, the scorer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sc2data import load_model  # noqa: E402
from sc2data._pysc2 import units  # noqa: E402
from sc2data.ground.errors import Sc2DataError  # noqa: E402
from sc2data.model.mem import (  # noqa: E402
    MEM,
    ModelConfig,
    flush_denormals,
    load_checkpoint,
    save_checkpoint,
    to_tensors,
    value_tables,
)
from sc2data.model.scorer import MEMScorer  # noqa: E402
from sc2data.schema import Schema  # noqa: E402
from sc2data.testing.synthetic_pairs import stacks  # noqa: E402
from tests.mem_helpers import SMALL_SCHEMA  # noqa: E402

VECTORS = np.random.default_rng(0).normal(size=(4, 5)).astype(np.float32)
WORDS = ("build", "a", "supply", "depot")
EVENTS = ["build_supply_depot", "build_barracks", "build_scv", "train_marine",
          "collect_minerals", None]


def _model(schema: Schema, mode: str = "embed", seed: int = 0, pool: int = 2
           ) -> tuple[MEM, object]:
    batch = stacks(schema, EVENTS, seed=seed)
    cfg = ModelConfig(categorical=mode, pool=pool)  # type: ignore[arg-type]
    torch.manual_seed(seed)
    return MEM(schema, value_tables(schema, [batch], cfg.max_table), VECTORS, cfg), batch


def test_unit_type_table_holds_the_ids_seen_and_small_layers_every_id() -> None:
    batch = stacks(SMALL_SCHEMA, EVENTS, seed=0)
    tables = value_tables(SMALL_SCHEMA, [batch], max_table=32)
    assert tables["screen/player_relative"] == [0, 1, 2, 3, 4]  # scale 5: every id
    assert tables["minimap/camera"] == [0, 1]
    assert set(tables["screen/unit_type"]) == {0, units.Terran.SCV, units.Terran.CommandCenter,
                                               units.Terran.SupplyDepot, units.Terran.Barracks,
                                               units.Terran.Marine, units.Neutral.MineralField}


@pytest.mark.parametrize("mode, screen, minimap", [
    # screen: unit_type 7 ids + "other" = 8, player_relative 5, hit points 1 scalar; ×2 frames
    ("onehot", 2 * (8 + 5 + 1), 2 * (5 + 2)),
    ("embed", 2 * (8 + 5 + 1), 2 * (5 + 2)),  # the one-hot image; embedded in the first conv
    ("scalar", 2 * (1 + 1 + 1), 2 * (1 + 1)),
])
def test_input_channels_follow_the_schema(mode: str, screen: int, minimap: int) -> None:
    m, _ = _model(SMALL_SCHEMA, mode)
    assert m.state.inputs["screen"].channels == screen
    assert m.state.inputs["minimap"].channels == minimap
    paper, _ = _model(Schema.paper(), mode)
    assert paper.state.inputs["screen"].channels > screen  # 13 layers, not 3


def test_embed_equals_a_per_layer_lookup_then_the_convolution() -> None:
    from torch.nn import functional as F

    from sc2data.model.mem import EmbeddedConv

    m, batch = _model(SMALL_SCHEMA, "embed", pool=1)
    inp = m.state.inputs["screen"]
    first = m.state.towers["screen"][0]
    assert isinstance(first, EmbeddedConv)
    x = to_tensors(m.state.pack(batch.arrays))
    with torch.no_grad():
        onehot = inp(x["screen.idx"], x["screen.scalar"])  # (B, C, H, W)
        embedded = torch.einsum("bchw,cd->bdhw", onehot, first.mixing())
        # at a pixel, the embedded image holds the layer's embedding row of the pixel's id
        ut, table = batch.layer("screen/unit_type"), m.tables["screen/unit_type"]
        per_frame = embedded.shape[1] // 2
        for frame in (0, 1):
            compact = table.index(int(ut[0, frame, 20, 20])) + 1  # +1: index 0 is "other"
            got = embedded[0, frame * per_frame + 1: frame * per_frame + 1 + 8, 20, 20]
            torch.testing.assert_close(got, first.embeds[0][compact])  # after 1 scalar layer
        hp = batch.layer("screen/unit_hit_points")[0, 1, 20, 20] / 1600
        assert float(embedded[0, per_frame, 20, 20]) == pytest.approx(hp)
        # and folding E into the kernel is the same function as embedding first
        explicit = F.conv2d(embedded, first.conv.weight, first.conv.bias, first.conv.stride)
        torch.testing.assert_close(first(onehot), explicit, rtol=1e-4, atol=1e-5)


def test_pooled_onehot_holds_each_ids_share_of_the_cell() -> None:
    m, batch = _model(SMALL_SCHEMA, "onehot", pool=2)
    inp = m.state.inputs["screen"]
    x = to_tensors(m.state.pack(batch.arrays))
    with torch.no_grad():
        img = inp(x["screen.idx"], x["screen.scalar"])
    assert img.shape[-2:] == (32, 32)
    ut = batch.layer("screen/unit_type")
    table = m.tables["screen/unit_type"]
    per_frame, n_scalar = img.shape[1] // 2, 1
    for frame in (0, 1):
        block = img[:, frame * per_frame + n_scalar: frame * per_frame + n_scalar + 8]
        for unit in (units.Terran.SCV, units.Terran.SupplyDepot):
            share = block[:, table.index(unit) + 1].sum((1, 2)).numpy()
            np.testing.assert_allclose(share * 4, (ut[:, frame] == unit).sum((1, 2)))
    hp = batch.layer("screen/unit_hit_points")[:, 0].reshape(6, 32, 2, 32, 2).mean((2, 4))
    np.testing.assert_allclose(img[:, 0].numpy(), hp / 1600, rtol=1e-5)


def test_nonspatial_features_are_signed_log1p_of_both_frames_and_change() -> None:
    m, batch = _model(SMALL_SCHEMA)
    seen: list[torch.Tensor] = []
    m.state.nonspatial[0].register_forward_hook(lambda mod, inp, out: seen.append(inp[0]))
    with torch.no_grad():
        m.state(to_tensors(m.state.pack(batch.arrays)))
    v = seen[0].numpy()
    player = batch.arrays["player"].astype(float)
    n, width = player.shape[-1], v.shape[1] // 3  # player (11) then score_cumulative (13)
    np.testing.assert_allclose(v[:, :n], np.log1p(player[:, 0]), rtol=1e-6)
    delta = player[:, 1] - player[:, 0]
    np.testing.assert_allclose(v[:, 2 * width:2 * width + n],
                               np.sign(delta) * np.log1p(np.abs(delta)), rtol=1e-6)


@pytest.mark.parametrize("pool", [1, 2])
def test_torch_packing_for_a_gpu_equals_numpy_packing(pool: int) -> None:
    m, batch = _model(Schema.paper(), "onehot", pool=pool)
    cpu = m.state.pack(batch.arrays)
    raw = to_tensors({k: batch.arrays[k] for k in m.state.keys()})
    dev = m.state.pack_torch(raw)
    assert set(cpu) == set(dev)
    for k in cpu:
        np.testing.assert_array_equal(dev[k].numpy(), cpu[k], err_msg=k)


def test_forward_gives_one_distance_per_pair_and_l2_skips_biases_and_words() -> None:
    m, batch = _model(SMALL_SCHEMA)
    x = to_tensors(m.state.pack(batch.arrays))
    ids, lengths = torch.tensor([[1, 2, 3, 4], [1, 0, 0, 0]]), torch.tensor([4, 1])
    d = m(x, {"ids": ids, "lengths": lengths}, torch.tensor([0, 1, 0, 1, 0, 1]))
    assert d.shape == (6,) and torch.isfinite(d).all() and (d >= 0).all()
    expected = sum((p ** 2).sum() for n, p in m.named_parameters()
                   if "bias" not in n and n != "command.words.weight")
    torch.testing.assert_close(m.l2(), expected)
    assert not m.command.words.weight.requires_grad


def test_checkpoint_reloads_to_identical_distances(tmp_path: Path) -> None:
    m, batch = _model(SMALL_SCHEMA, "onehot")
    save_checkpoint(tmp_path / "best.pt", m, WORDS, {"commands": []})
    texts = ["build a supply depot", "depot"]
    m.eval()
    before = MEMScorer(m, {"words": WORDS}, torch.device("cpu")).distances(batch, texts)
    np.testing.assert_array_equal(load_model(tmp_path / "best.pt").distances(batch, texts), before)
    x = to_tensors(m.state.pack(batch.arrays))
    ids = torch.tensor([[1, 2, 3, 4], [4, 0, 0, 0]])
    with torch.no_grad():
        d0 = m(x, {"ids": ids, "lengths": torch.tensor([4, 1])}, torch.zeros(6, dtype=torch.long))
    np.testing.assert_allclose(before[:, 0], d0.numpy(), rtol=1e-6)
    again, _ = load_checkpoint(tmp_path / "best.pt")
    with torch.no_grad():
        np.testing.assert_array_equal(again(x, {"ids": ids, "lengths": torch.tensor([4, 1])},
                                            torch.zeros(6, dtype=torch.long)).numpy(), d0.numpy())


def test_a_checkpoints_denormal_weights_load_as_zero_and_change_no_distance(
        tmp_path: Path) -> None:
    """Weights the penalty left below float32's smallest normal (slow on a CPU) load as 0."""
    torch.set_flush_denormal(False)  # as a fresh process is (training in this one sets it)
    m, batch = _model(SMALL_SCHEMA, "onehot")
    tiny = torch.finfo(torch.float32).tiny
    with torch.no_grad():
        w = m.state.head.weight
        w[0, :8] = tiny / 4  # denormal
        w[1, :8] = -tiny / 8
    assert ((w.abs() < tiny) & (w != 0)).sum() == 16
    save_checkpoint(tmp_path / "best.pt", m, WORDS, {"commands": []})
    m.eval()
    texts = ["build a supply depot", "depot"]
    before = MEMScorer(m, {"words": WORDS}, torch.device("cpu")).distances(batch, texts)
    loaded, _ = load_checkpoint(tmp_path / "best.pt")
    for v in loaded.state_dict().values():
        if v.is_floating_point():
            assert not ((v.abs() < tiny) & (v != 0)).any()
    head = loaded.state.head.weight.detach()
    assert float(head[0, 0]) == 0.0
    assert float(head[2, 0]) == float(w[2, 0].detach())  # normal values as they were
    np.testing.assert_allclose(load_model(tmp_path / "best.pt").distances(batch, texts), before,
                               rtol=1e-6)
    ints = {"n": torch.tensor([1, 2])}
    assert flush_denormals(ints)["n"].tolist() == [1, 2]  # integer tensors untouched


def test_scorer_batches_broadcasts_and_refuses_bad_input(tmp_path: Path) -> None:
    m, batch = _model(SMALL_SCHEMA)
    save_checkpoint(tmp_path / "best.pt", m, WORDS, {})
    s = load_model(tmp_path / "best.pt")
    one = s.distance(batch, "build a depot")
    each = s.distance(batch, ["build a depot"] * len(batch))
    np.testing.assert_allclose(one, each, rtol=1e-6)
    np.testing.assert_allclose(s.distances(batch, ["build a depot", "a"])[:, 0], one, rtol=1e-6)
    assert s.matches(batch, "build a depot").dtype == bool
    with pytest.raises(Sc2DataError, match="stacks and 2 texts"):
        s.distance(batch, ["a", "depot"])
    with pytest.raises(Sc2DataError, match="no word in the model's vocabulary"):
        s.distance(batch, "qqzx")
    partial = {k: v for k, v in batch.arrays.items() if k != "screen/unit_type"}
    with pytest.raises(Sc2DataError, match="screen/unit_type"):
        s.distance(partial, "depot")


def test_checkpoint_of_another_schema_version_is_refused(tmp_path: Path) -> None:
    m, _ = _model(SMALL_SCHEMA)
    save_checkpoint(tmp_path / "best.pt", m, WORDS, {})
    blob = torch.load(tmp_path / "best.pt", weights_only=True)
    blob["schema"]["version"] = 99
    torch.save(blob, tmp_path / "best.pt")
    with pytest.raises(Sc2DataError, match="schema version 99"):
        load_model(tmp_path / "best.pt")
    (tmp_path / "best.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(Sc2DataError, match="not a readable checkpoint"):
        load_model(tmp_path / "best.pt")


# -- the Python API checks what the CLI checks -----------------------------------------------------

def _flip_a_weight_bit(path: Path) -> None:
    """Flip one bit inside the largest tensor record of a torch checkpoint (zip) archive."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        rec = max(z.infolist(), key=lambda i: i.file_size)
    data = bytearray(path.read_bytes())
    name_len, extra_len = (int.from_bytes(data[rec.header_offset + o:rec.header_offset + o + 2],
                                          "little") for o in (26, 28))
    at = rec.header_offset + 30 + name_len + extra_len + rec.file_size // 2
    data[at] ^= 0x40
    path.write_bytes(bytes(data))


def test_a_checkpoint_file_is_checked_by_content(tmp_path: Path) -> None:
    """``load_model(FILE)``: in a run, against its state.json; outside one, each record's CRC;
    anywhere, finite weights. Each flip below loaded before, giving wrong distances."""
    from tests.mem_helpers import tiny_pairset, train_tiny

    run = train_tiny(tiny_pairset(tmp_path / "pairs"), tmp_path / "run", epochs=1)
    loose = tmp_path / "loose.pt"
    loose.write_bytes((run / "best.pt").read_bytes())
    assert load_model(run / "best.pt") is not None and load_model(loose) is not None  # controls
    _flip_a_weight_bit(run / "best.pt")
    with pytest.raises(Sc2DataError, match=r"best.pt is missing, damaged or was replaced \(its "
                                           r"sha256 differs from state.json\)"):
        load_model(run / "best.pt")
    _flip_a_weight_bit(loose)
    with pytest.raises(Sc2DataError, match=r"loose.pt is damaged: its record .* fails its "
                                           r"CRC-32 check"):
        load_model(loose)
    m, _ = _model(SMALL_SCHEMA)
    with torch.no_grad():
        next(p for n, p in m.named_parameters() if n.startswith("state.")).view(-1)[3] = \
            float("inf")
    save_checkpoint(tmp_path / "diverged.pt", m, WORDS, {})  # whole, with valid CRCs
    with pytest.raises(Sc2DataError, match=r"diverged.pt holds non-finite weights \(state\."):
        load_model(tmp_path / "diverged.pt")


def test_the_scorer_refuses_inputs_it_cannot_score(tmp_path: Path) -> None:
    """NaN or infinite vectors, ids out of a layer's range, wrong dtypes or batch sizes: one
    Sc2DataError naming the key, never a NaN or silently wrong distance."""
    m, batch = _model(SMALL_SCHEMA)
    save_checkpoint(tmp_path / "best.pt", m, WORDS, {})
    s = load_model(tmp_path / "best.pt")
    good = dict(batch.arrays)
    before = s.distance(good, "build a depot")
    assert np.isfinite(before).all()
    # the same ids in a wider integer dtype, and the vectors as floats, read the same
    wide = {k: v.astype(np.int64) if k.startswith(("screen/", "minimap/")) else
            v.astype(np.float64) for k, v in good.items()}
    np.testing.assert_allclose(s.distance(wide, "build a depot"), before, rtol=1e-6)

    def bad(key: str, value: np.ndarray) -> dict[str, np.ndarray]:
        return {**good, key: value}

    nan = good["player"].astype(np.float32)
    nan[2, 1, 3] = np.nan
    inf = good["player"].astype(np.float64)
    inf[0, 0, 0] = np.inf
    high = good["screen/player_relative"].copy()
    high[1, 0, 5, 5] = 7  # uint8 holds it; player_relative has 5 ids
    negative = good["screen/unit_type"].astype(np.int32)
    negative[0, 1, 0, 0] = -1
    cases = {
        "nan": (bad("player", nan), r"player holds nan \(stack 2, field 'food_used'\)"),
        "inf": (bad("player", inf), r"player holds inf \(stack 0, field 'player_id'\)"),
        "id-high": (bad("screen/player_relative", high),
                    r"screen/player_relative holds 7, outside the layer's range \[0, 5\)"),
        "id-negative": (bad("screen/unit_type", negative),
                        r"screen/unit_type holds -1, outside the layer's range"),
        "float-layer": (bad("screen/unit_type", good["screen/unit_type"].astype(np.float32)),
                        r"screen/unit_type holds float32 values; the model reads integer ids"),
        "text-vector": (bad("player", good["player"].astype(str)), r"player holds <U\d+ values"),
        "batch": (bad("player", good["player"][:2]), r"disagree on the batch size"),
    }
    for arrays, message in cases.values():
        with pytest.raises(Sc2DataError, match=message):
            s.distance(arrays, "build a depot")
