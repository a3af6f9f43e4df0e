"""``avard explain``'s options: analyze's (its base is analyze's fit with the same options)
and what explain adds."""

from __future__ import annotations

from dataclasses import dataclass

from avard.core.analysis.options import AnalyzeOptions

__all__ = ["DEFAULT_EXPLAIN", "ExplainOptions"]


@dataclass(frozen=True)
class ExplainOptions(AnalyzeOptions):
    """``temperature``: the one temperature channel to use (its compensation is then reported
    whatever its test says); ``heldout`` False skips the held-out measure (``avard analyze
    --temperature`` needs only the thermal fit)."""

    temperature: str | None = None
    heldout: bool = True


#: explain's defaults (what `avard explain FILE` does).
DEFAULT_EXPLAIN = ExplainOptions()
