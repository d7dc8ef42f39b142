"""Instruction tokens: a word vocabulary built from the training instructions.

Tokenising lower-cases, strips punctuation and splits on whitespace. Id 0 is padding, id 1 is
``<unk>`` (every word not seen in training). Training replaces words by ``<unk>`` at a small rate
(word dropout), so an unseen word in a paraphrase is a known "don't know" rather than noise.

Policy for unseen wording (measured, see docs/planner.md): the planner accepts an instruction while at
most ``max_unknown_fraction`` of its words are unknown and at least one word is known; beyond that it
refuses with PlanningError instead of guessing a task.
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from tcot_hybrid.errors import PlanningError

PAD, UNK = "<pad>", "<unk>"
_PUNCT = re.compile(r"[^\w\s]")


def words(text: str) -> list[str]:
    """Lower-cased words of ``text`` with punctuation removed."""
    if not isinstance(text, str):
        raise PlanningError(f"instruction must be a string, got {type(text).__name__}")
    return _PUNCT.sub(" ", text.lower()).split()


@dataclass(frozen=True)
class Vocabulary:
    """Word list; index = token id. ``tokens[0] == "<pad>"``, ``tokens[1] == "<unk>"``."""

    tokens: tuple[str, ...]

    def __post_init__(self) -> None:
        if len(self.tokens) < 2 or self.tokens[0] != PAD or self.tokens[1] != UNK:
            raise ValueError(f"vocabulary must start with {PAD!r}, {UNK!r}; got {self.tokens[:2]}")
        if len(set(self.tokens)) != len(self.tokens):
            raise ValueError("vocabulary has duplicate words")
        object.__setattr__(self, "_index", {w: i for i, w in enumerate(self.tokens)})

    @classmethod
    def build(cls, instructions: Iterable[str]) -> Vocabulary:
        seen = sorted({w for text in instructions for w in words(text)})
        return cls((PAD, UNK, *seen))

    def __len__(self) -> int:
        return len(self.tokens)

    def encode(self, text: str, max_tokens: int) -> tuple[np.ndarray, int, int]:
        """(ids padded/truncated to ``max_tokens``, number of words, number of unknown words)."""
        ws = words(text)
        ids = [self._index.get(w, 1) for w in ws]  # type: ignore[attr-defined]
        unknown = sum(i == 1 for i in ids)
        out = np.zeros(max_tokens, dtype=np.int64)
        ids = ids[:max_tokens]
        out[: len(ids)] = ids
        return out, len(ws), unknown

    def encode_checked(self, text: str, max_tokens: int, *, max_unknown_fraction: float) -> np.ndarray:
        """Encode, refusing (PlanningError) an instruction that is empty, too long, has no known word or
        more than ``max_unknown_fraction`` unknown words."""
        ids, n, unknown = self.encode(text, max_tokens)
        if n == 0:
            raise PlanningError("instruction is empty")
        if n > max_tokens:
            raise PlanningError(f"instruction has {n} words; the planner reads at most {max_tokens}")
        if unknown == n or unknown / n > max_unknown_fraction:
            unk = [w for w in words(text) if w not in self._index]  # type: ignore[attr-defined]
            raise PlanningError(
                f"instruction {text!r} has {unknown} of {n} words the planner never saw in training "
                f"({', '.join(unk)}); allowed fraction {max_unknown_fraction}. Known words: "
                f"{', '.join(self.tokens[2:])}")
        return ids
