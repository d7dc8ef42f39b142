"""Instruction encoding (learning/vocab.py) on LIBERO's instructions: words, unknown words, empty and very long
instructions, and the planner's refusal rule."""
import numpy as np
import pytest

from tcot_hybrid.errors import PlanningError
from tcot_hybrid.learning.vocab import UNK, Vocabulary, words

LIBERO = ["pick up the black bowl between the plate and the ramekin and place it on the plate",
          "open the middle drawer of the cabinet", "turn on the stove",
          "put both the alphabet soup and the tomato sauce in the basket"]
V = Vocabulary.build(LIBERO)


def test_words_are_lower_cased_without_punctuation_and_shared_across_instructions():
    assert words("Turn ON the stove!") == ["turn", "on", "the", "stove"]
    assert V.tokens.count("the") == 1  # a word, not a whole-string lookup
    ids, n, unk = V.encode("Turn on the stove.", 24)
    assert (n, unk) == (4, 0) and ids[4:].sum() == 0
    # a reworded instruction reuses the known words' ids
    ids2, _, unk2 = V.encode("turn the stove on", 24)
    assert unk2 == 0 and sorted(ids2[:4].tolist()) == sorted(ids[:4].tolist())


def test_unknown_words_become_unk_and_too_many_are_refused_naming_them():
    ids, n, unk = V.encode("open the top drawer of the cabinet", 24)
    assert (n, unk) == (7, 1) and ids[2] == V.tokens.index(UNK)
    V.encode_checked("open the top drawer of the cabinet", 24, max_unknown_fraction=0.5)  # 1 of 7: accepted
    with pytest.raises(PlanningError, match=r"3 of 4 words.*\(ouvre, le, tiroir\)") as e:
        V.encode_checked("ouvre le tiroir cabinet", 24, max_unknown_fraction=0.5)
    assert "Known words" in str(e.value) and "drawer" in str(e.value)
    with pytest.raises(PlanningError, match="never saw"):
        V.encode_checked("xyzzy", 24, max_unknown_fraction=0.9)  # no known word at all


@pytest.mark.parametrize("text", ["", "   ", "?!.,", "\n\t"])
def test_empty_instructions_are_refused(text):
    ids, n, unk = V.encode(text, 24)
    assert n == 0 and unk == 0 and not ids.any()
    with pytest.raises(PlanningError, match="empty"):
        V.encode_checked(text, 24, max_unknown_fraction=0.5)


def test_very_long_instructions_are_truncated_by_encode_and_refused_by_the_planner_rule():
    long = " ".join(["pick up the black bowl and place it on the plate"] * 500)  # 5500 words
    ids, n, unk = V.encode(long, 24)
    assert n == 5500 and unk == 0 and ids.shape == (24,) and (ids > 0).all()
    with pytest.raises(PlanningError, match="5500 words; the planner reads at most 24"):
        V.encode_checked(long, 24, max_unknown_fraction=0.5)
    # exactly max_tokens words is fine
    V.encode_checked(" ".join(["the"] * 24), 24, max_unknown_fraction=0.5)


def test_non_string_instruction_is_refused():
    with pytest.raises(PlanningError, match="must be a string, got int"):
        V.encode(42, 24)
    with pytest.raises(PlanningError, match="must be a string, got NoneType"):
        V.encode_checked(None, 24, max_unknown_fraction=0.5)


def test_encoding_is_deterministic_and_vocabulary_order_independent_of_input_order():
    assert Vocabulary.build(LIBERO[::-1]) == V
    a, _, _ = V.encode(LIBERO[0], 24)
    b, _, _ = V.encode(LIBERO[0], 24)
    assert np.array_equal(a, b)
