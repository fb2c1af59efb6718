"""The presets a run's algorithm settings start from (`SwarmCoDeConfig.preset`,
`config.preset_config`)."""

from __future__ import annotations

from typing import Any

#: Algorithm settings of each preset, over the defaults of `SwarmCoDeConfig` ("default" is
#: those defaults). "paper": our reading of the paper's text with nothing beyond it: every
#: species the tags accept is a partner from its founding, a focal's slots are re-filled from
#: any partner, offspring quotas proportional to each species' total fitness, the effector
#: resampled as the tiers are (docs/MODEL.md, "Presets").
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "paper": {
        "partners_per_niche": "all",
        "partner_admission": "open",
        "quota_size_exponent": None,
        "p_effector": None,
        "essential_floor": 0,
    },
}
