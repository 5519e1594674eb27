"""Submission metadata: who submits what, as shown on the leaderboard.

Strings are length-limited and free of control characters (and of bidirectional
overrides, which can make a name render as another one) here; they are escaped wherever
they are rendered (HTML, terminal, CSV).
"""

from __future__ import annotations

import re
import unicodedata
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

MAX_NAME_CHARS: int = 64
MAX_AUTHORS_CHARS: int = 256
MAX_URL_CHARS: int = 512
MAX_DESCRIPTION_CHARS: int = 2000

# Bidirectional-override and isolate characters can make a name render as another one.
_BIDI_CONTROLS = set("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def _check_text(value: str, what: str, *, multiline: bool) -> str:
    """Reject control characters (newlines/tabs allowed only in multi-line fields)."""
    for char in value:
        if multiline and char in "\n\t":
            continue
        if unicodedata.category(char) == "Cc" or char in _BIDI_CONTROLS:
            raise ValueError(
                f"{what} contains the control character {char!r} (U+{ord(char):04X}); "
                f"only printable text is allowed"
            )
    return value


class SubmissionMetadata(BaseModel):
    """Who submits what; shown on the leaderboard.

    Attributes:
        name: Display name, 1–64 printable characters.
        authors: Free text, at most 256 characters.
        url: Optional ``http://`` or ``https://`` link (paper, code), at most 512 characters.
        description: Free text, at most 2000 characters (newlines allowed).
        track: ``"A"`` (link trust) or ``"B"`` (full estimator).
        privileged: True when the method reads privileged information; privileged methods
            are listed apart from the ranking.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(min_length=1, max_length=MAX_NAME_CHARS)
    authors: str = Field(default="", max_length=MAX_AUTHORS_CHARS)
    url: str | None = Field(default=None, max_length=MAX_URL_CHARS)
    description: str = Field(default="", max_length=MAX_DESCRIPTION_CHARS)
    track: Literal["A", "B"]
    privileged: bool = False

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        if value != value.strip():
            raise ValueError(f"name {value!r} has leading or trailing whitespace")
        return _check_text(value, "name", multiline=False)

    @field_validator("authors")
    @classmethod
    def _authors(cls, value: str) -> str:
        return _check_text(value, "authors", multiline=False)

    @field_validator("description")
    @classmethod
    def _description(cls, value: str) -> str:
        return _check_text(value, "description", multiline=True)

    @field_validator("url")
    @classmethod
    def _url(cls, value: str | None) -> str | None:
        if value is None or value == "":
            return None
        if not re.match(r"^https?://[^\s\"'<>`]+$", value):
            raise ValueError(
                f"url {value!r} must start with http:// or https:// and contain no "
                f"whitespace, quotes or angle brackets"
            )
        return value


__all__ = ["MAX_AUTHORS_CHARS", "MAX_DESCRIPTION_CHARS", "MAX_NAME_CHARS", "MAX_URL_CHARS", "SubmissionMetadata"]
