"""Physical effects a model configuration may add (``ModelConfig.effects``).

The registry is empty until the discovery workflow brings its library of
candidate effects; until then any named effect is refused rather than
silently ignored (an unknown name would otherwise be recorded in the
provenance of a run it never touched).
"""

from __future__ import annotations

from typing import Any

from ..registry import Registry

EFFECTS: Registry[Any] = Registry("physical effect")
