"""The JSON field types of result records: strict (no string is read as a number, no bool as an
integer), finite, and with the ranges each kind of value has, so that the records' typed models
(`records`, `provenance`) say every rule once and their JSON Schema publishes it.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import ConfigDict, Field, Strict

#: The pydantic settings of every record part: no NaN or infinity anywhere; unknown keys are
#: ignored (a newer field in an older reader's way is not an error).
RECORD_CONFIG = ConfigDict(allow_inf_nan=False, extra="ignore")

Text = Annotated[str, Strict()]
Name = Annotated[str, Strict(), Field(min_length=1)]
Count = Annotated[int, Strict(), Field(ge=0)]
Number = Annotated[float, Strict()]
Amount = Annotated[float, Strict(), Field(ge=0)]
Rate = Annotated[float, Strict(), Field(ge=0, le=1)]
