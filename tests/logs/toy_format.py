"""A toy log format, as a lab would add one: a ``.toy`` JSON file of episodes, each a skill, its
sample times and one list per column. One module: its section, its reader; the test registers it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import ClassVar, Iterator, Literal

import numpy as np

from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Address, Mapping, Section
from neural_asm.logs.recorded import Recorded
from neural_asm.logs.resample import EpisodeResampler, Group


class ToySection(Section):
    kind: Literal["toy"] = "toy"
    address: ClassVar[Address] = "column"


class ToyReader:
    kind = "toy"
    named = "a toy file (.toy)"
    section = ToySection

    def recognises(self, source: Path) -> bool:
        return source.suffix == ".toy"

    def read(self, source: Path, mapping: Mapping, skip_bad: bool) -> Iterator[Recorded | str]:
        group = Group("toy rows", tuple(mapping.channels), tuple(range(len(mapping.channels))))
        for number, episode in enumerate(json.loads(source.read_text())):
            what = f"{source.name} episode {number}"
            try:
                resampler = EpisodeResampler([group], mapping.timing, what)
                values = np.array([episode["columns"][c.column] for c in mapping.channels], np.float64).T
                resampler.add(0, np.array(episode["t"], np.float64), values=values)
                yield Recorded(resampler.finish(), episode["skill"], what, float(episode["t"][0]), number)
            except (LogError, KeyError) as exc:
                if not skip_bad:
                    raise LogError(f"{what}: {exc}") from None
                yield f"skipped {what}: {exc}"
