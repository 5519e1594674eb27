"""What an attribution is attributed to: the observation features, their groups, the baselines.

Every Track A method sees, per channel, the F = 11 features of
``swarmloc.envs.world.observation`` (innovation, predicted distance, previous trust, IMU jerk,
NIS, the five-column one-hot of the channel kind, valid) next to the raw fields they are
built from. An attribution splits the channel's trust α(x) − α(x̄) over the features,
where x̄ is a **baseline**: the same channel with some features switched to reference
values. Two baselines are defined:

| name | innovation | predicted distance | previous trust | IMU jerk | NIS | kind | valid |
|---|---|---|---|---|---|---|---|
| ``nominal`` (default) | 0 | observed | 1 | 0 | 0 | observed | observed |
| ``zeros`` | 0 | 0 | 0 | 0 | 0 | 0 | 0 |

``nominal`` is a quiet, fully trusted channel of the same kind at the same range: a
perfectly consistent measurement (zero innovation and NIS) from a steady UAV (zero jerk)
on a link that had full trust. Its attributions answer "what in this channel's evidence
moved α away from where a quiet link would be", and they sum to α(x) − α(nominal).
Distance, kind and valid describe which link it is rather than evidence against it, so
they stay as observed and get no attribution. ``zeros`` is Captum's default (every
feature 0, an absent channel): every feature can get attribution, but the reference is a
channel that does not exist.

The seven **groups** (the kind one-hot counted as one feature, "channel kind") are the
players of the model-agnostic Shapley game and the rows of figures and tables.
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.channels import N_KINDS
from swarmloc.envs.world.observation import (
    DISTANCE,
    FEATURE_NAMES,
    INNOVATION,
    JERK,
    KIND0,
    N_FEATURES,
    NIS,
    PREV_TRUST,
    SCALE_DISTANCE,
    SCALE_INNOVATION,
    SCALE_JERK,
    SCALE_NIS,
    VALID,
    unsquash,
)

#: display name → feature columns; the kind one-hot is one group
FEATURE_GROUPS: dict[str, tuple[int, ...]] = {
    "innovation": (INNOVATION,),
    "predicted distance": (DISTANCE,),
    "previous trust": (PREV_TRUST,),
    "IMU jerk": (JERK,),
    "NIS": (NIS,),
    "channel kind": tuple(range(KIND0, KIND0 + N_KINDS)),
    "valid": (VALID,),
}
GROUP_NAMES = tuple(FEATURE_GROUPS)
N_GROUPS = len(GROUP_NAMES)
#: ``(F,)`` group index of every feature column
FEATURE_GROUP = np.array([next(g for g, cols in enumerate(FEATURE_GROUPS.values()) if f in cols)
                          for f in range(N_FEATURES)], dtype=np.int64)

BASELINES = ("nominal", "zeros")
#: squash scale of each magnitude feature (its raw field is ``unsquash(feature, scale)``)
FEATURE_SCALE = {INNOVATION: SCALE_INNOVATION, DISTANCE: SCALE_DISTANCE, JERK: SCALE_JERK, NIS: SCALE_NIS}

__all__ = ["BASELINES", "FEATURE_GROUP", "FEATURE_GROUPS", "FEATURE_NAMES", "GROUP_NAMES", "N_GROUPS",
           "baseline_features", "group_attributions", "raw_value"]


def check_baseline(name: str) -> str:
    """Return ``name`` if it is a known baseline.

    Raises:
        ValueError: naming the allowed ones.
    """
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; choose one of {', '.join(BASELINES)} "
                         f"(see swarmloc.bench.explain.features)")
    return name


def baseline_features(obs: np.ndarray, name: str = "nominal") -> np.ndarray:
    """The baseline x̄ of every channel of ``obs``.

    Args:
        obs: ``(..., F)`` observed features.
        name: ``nominal`` or ``zeros`` (see the module docstring).

    Returns:
        ``(..., F)`` float64 baseline features.
    """
    check_baseline(name)
    obs = np.asarray(obs, dtype=np.float64)
    if obs.shape[-1] != N_FEATURES:
        raise ValueError(f"obs must have F = {N_FEATURES} features in its last axis, got shape {obs.shape}")
    if name == "zeros":
        return np.zeros_like(obs)
    base = obs.copy()
    base[..., [INNOVATION, JERK, NIS]] = 0.0
    base[..., PREV_TRUST] = 1.0
    return base


def raw_value(feature: int, value: np.ndarray) -> np.ndarray:
    """The raw ``TrustInput`` field value that a feature value stands for.

    Magnitudes are unsquashed (innovation → ‖y‖ [m], predicted distance [m], jerk
    [m/s²], NIS); previous trust is itself; valid is ``value > 0.5``. The kind columns
    have no raw field (a method learns the kinds from the layout at ``reset``).
    """
    value = np.asarray(value, dtype=np.float64)
    if feature in FEATURE_SCALE:
        return unsquash(value, FEATURE_SCALE[feature])
    if feature == PREV_TRUST:
        return value
    if feature == VALID:
        return value > 0.5
    raise ValueError(f"feature {feature} ({FEATURE_NAMES[feature]}) has no raw TrustInput field")


def group_attributions(values: np.ndarray) -> np.ndarray:
    """Sum per-feature attributions ``(..., F)`` into the seven groups ``(..., G)``."""
    values = np.asarray(values, dtype=np.float64)
    out = np.zeros(values.shape[:-1] + (N_GROUPS,))
    for g, cols in enumerate(FEATURE_GROUPS.values()):
        out[..., g] = values[..., list(cols)].sum(axis=-1)
    return out
