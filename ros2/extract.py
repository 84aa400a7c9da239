"""A topic's channel values from each live message, at the rate a robot sends them: the bag
reader's checked extractor (``logs.fields.extractor``) reads the first message of each layout
(a JointState's ``name[]``, which decides where a ``key`` points) and, having accepted it,
leaves the next ones of that layout to the attribute paths and element indices it resolved.
Any message those do not fit goes back to the checked extractor, which says what is wrong."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from operator import attrgetter
from typing import Any

import numpy as np

from neural_asm.logs.fields import extractor
from neural_asm.logs.mapping import Channel

_Plan = list[tuple[Callable[[Any], Any], int | None]]  # each channel's field and element (None: the value)


class Extractor:
    """``extractor(channels, topic, msgtype)``'s values, without looking a layout up twice."""

    def __init__(self, channels: Sequence[Channel], topic: str, msgtype: str) -> None:
        self.channels = list(channels)
        self.checked = extractor(self.channels, topic, msgtype)
        self.plans: dict[tuple[str, ...], _Plan] = {}

    def __call__(self, message: Any) -> np.ndarray:
        layout = tuple(getattr(message, "name", ()))
        plan = self.plans.get(layout)
        if plan is not None:
            try:
                return np.array([get(message) if i is None else get(message)[i] for get, i in plan], np.float64)
            except (IndexError, TypeError):
                pass  # arrays shorter than this layout's: the checked extractor names what is missing
        values = self.checked(message)
        self.plans[layout] = [(attrgetter(ch.field or ""), layout.index(ch.key) if ch.key is not None else ch.index)
                              for ch in self.channels]
        return values
