"""Model-agnostic attributions: Shapley value sampling (Captum) over a method's ``act``.

Any Track A method — a classical rule, a torch network, a user's black box — is probed
through its own ``act`` only. The players of each channel's game are the seven feature
groups (``features.GROUP_NAMES``: the kind one-hot counts as one); a coalition S sees
its features as observed and the others at the baseline x̄, and the worth of S is the
method's trust on the channel. Captum's ``ShapleyValueSampling`` averages the marginal
contributions over ``n_samples`` random orders of the seven groups; every order's
contributions telescope to α(x) − α(x̄), so the sampled values add up exactly, and a
feature the method never reads gets exactly zero. (Captum's ``KernelShap`` estimates the
same values by a weighted regression, one input at a time; sampling orders lets one call
cover every channel of a step.)

**Probing a stateful method.** A method may keep state between steps (a Markov
smoother's memory, a seeded generator). Each step's probes must see the state the method
had at that step, so a *shadow* copy of the method runs a batch of C = B·N·L·G copies of
the episodes — copy c holds one channel's probe — and sees the recorded inputs at every
step, which keeps each copy's state equal to the method's own (the Track A contract: an
episode gives the same trust alone or batched). The probes of a step run on a deep copy
of the shadow (torch modules are shared, not copied: they are the parameters), so the
shadow itself only ever sees the recorded path. A probe changes the raw ``TrustInput``
fields along with the features (``features.raw_value``); the channel kind has no raw
field (a method reads the kinds from the layout at ``reset``).
"""

from __future__ import annotations

import copy
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from captum.attr import ShapleyValueSampling

from swarmloc.agents.protocols import TrustInput
from swarmloc.envs.world.observation import DISTANCE, INNOVATION, JERK, NIS, PREV_TRUST, VALID

from swarmloc.bench.explain.episode import Episode
from swarmloc.bench.explain.features import FEATURE_GROUP, FEATURE_GROUPS, N_GROUPS, raw_value

#: TrustInput field fed by each feature (jerk is per UAV: a probe sets its UAV's jerk)
_RAW_FIELD = {INNOVATION: "resid", DISTANCE: "pred", PREV_TRUST: "applied", NIS: "nis", VALID: "valid"}


def _shared_modules(obj: Any) -> dict[int, Any]:
    """A deepcopy memo that maps every torch module reachable from ``obj`` to itself."""
    nn = sys.modules.get("torch.nn")
    memo: dict[int, Any] = {}
    if nn is None:
        return memo
    stack, seen = [obj], set()
    while stack:
        item = stack.pop()
        if id(item) in seen:
            continue
        seen.add(id(item))
        if isinstance(item, nn.Module):
            memo[id(item)] = item
        elif isinstance(item, (list, tuple, set)):
            stack.extend(item)
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif hasattr(item, "__dict__") and not isinstance(item, type):
            stack.extend(vars(item).values())
    return memo


def fresh_copy(method: Any, memo: dict[int, Any] | None = None) -> Any:
    """A deep copy of a method that shares its torch modules (see :func:`_shared_modules`)."""
    return copy.deepcopy(method, dict(_shared_modules(method) if memo is None else memo))


@dataclass(frozen=True)
class ShapleyResult:
    """Sampled Shapley values of the explained rows.

    Attributes:
        values: ``(R, F)`` attributions (a group's value on the columns where x ≠ x̄).
        trust, baseline_trust: ``(R,)`` the method's α(x) and α(x̄).
        delta: ``(R,)`` Σ attributions − (α(x) − α(x̄)) (rounding only).
        method_trust: ``(T, B, N, L)`` the method's own trust on the recorded inputs.
        batch_gap: max |shadow copy's α − the method's α| on the recorded inputs.
    """

    values: np.ndarray
    trust: np.ndarray
    baseline_trust: np.ndarray
    delta: np.ndarray
    method_trust: np.ndarray
    batch_gap: float


class _Prober:
    """Turns Captum's probe rows into one batched ``TrustInput`` of the shadow's C copies."""

    def __init__(self, episode: Episode, rows: tuple[np.ndarray, np.ndarray, np.ndarray], copies: int) -> None:
        self.episode = episode
        self.b, self.n, self.l = rows
        self.m = len(self.b)
        self.copies = copies
        self.copy_episode = np.tile(self.b, copies // self.m)

    def tiled(self, k: int) -> dict[str, np.ndarray]:
        """The recorded inputs of step k, one per shadow copy."""
        ep, e = self.episode, self.copy_episode
        return {"obs": ep.obs[k][e], "resid": ep.resid[k][e], "pred": ep.pred[k][e], "nis": ep.nis[k][e],
                "applied": ep.applied[k][e], "jerk": ep.jerk[k][e], "valid": ep.valid[k][e]}

    def trust_input(self, k: int, fields: dict[str, np.ndarray]) -> TrustInput:
        ep = self.episode
        return TrustInput.view(fields["obs"], fields["resid"], fields["pred"], fields["nis"], fields["applied"],
                               fields["jerk"], fields["valid"], float(ep.times[k]), k + 1)

    def probe(self, k: int, tiled: dict[str, np.ndarray], x: np.ndarray, probes: np.ndarray) -> dict[str, np.ndarray]:
        """Fields of C copies where copy c has its row's channel set to ``probes[c]``.

        A probe value is the observed feature or the baseline's (0, 1 or an observed
        value), so writing it into the float32 observation is exact.
        """
        fields = {name: value.copy() for name, value in tiled.items()}
        c = np.arange(len(probes))
        r = c % self.m
        n, l = self.n[r], self.l[r]
        fields["obs"][c, n, l] = probes
        # a feature at its observed value keeps its exact raw field; one at the baseline gets the baseline's
        moved = probes != x[r]
        for feature, name in _RAW_FIELD.items():
            sel = moved[:, feature]
            fields[name][c[sel], n[sel], l[sel]] = raw_value(feature, probes[sel, feature])
        sel = moved[:, JERK]
        fields["jerk"][c[sel], n[sel]] = raw_value(JERK, probes[sel, JERK])
        return fields


def shapley_sampling(method: Any, episode: Episode, baseline: np.ndarray, explained: np.ndarray,
                     n_samples: int = 25, seed: int = 0) -> ShapleyResult:
    """Sampled Shapley values of every explained channel at every step of a recorded episode.

    Args:
        method: a fresh Track A method instance (copies of it are reset here; it is not changed).
        episode: the recorded inputs.
        baseline: ``(T, B, N, L, F)`` baseline features x̄.
        explained: ``(N, L)`` bool, the channels to explain (of every UAV and episode).
        n_samples: random orders of the seven groups per channel and step.
        seed: seed of the orders (torch's generator, forked: the global one is untouched).

    Returns:
        The ``ShapleyResult`` of the rows in (step, episode, UAV, channel) order.
    """
    n_t = episode.n_steps
    n_b, n, n_l, n_f = episode.obs.shape[1:]
    rows = np.nonzero(np.broadcast_to(explained, (n_b, n, n_l)))
    m = len(rows[0])
    copies = m * N_GROUPS  # one Captum call holds a whole order: G probes of every row
    keys = episode.keys
    main, shadow = fresh_copy(method), fresh_copy(method)
    main.reset(n_b, episode.layout, keys)
    prober = _Prober(episode, rows, copies)
    shadow.reset(copies, episode.layout, keys[prober.copy_episode])
    memo = _shared_modules(shadow)
    mask = torch.as_tensor(FEATURE_GROUP)[None]
    values = np.zeros((n_t, m, n_f))
    trust, base_trust = np.zeros((n_t, m)), np.zeros((n_t, m))
    method_trust = np.zeros((n_t, n_b, n, n_l))
    batch_gap = 0.0
    pick = (np.arange(copies), np.tile(rows[1], N_GROUPS), np.tile(rows[2], N_GROUPS))

    for k in range(n_t):
        x = episode.obs[k][rows].astype(np.float64)
        xb = baseline[k][rows]
        tiled = prober.tiled(k)

        def forward(probes: torch.Tensor, k: int = k, x: np.ndarray = x, tiled: dict = tiled) -> torch.Tensor:
            p = probes.detach().numpy()
            # the shadow's batch is fixed: a short call (the baseline alone) is padded by repetition
            padded = np.concatenate([p, np.resize(p, (copies - len(p), n_f))]) if len(p) < copies else p
            trial = fresh_copy(shadow, memo)
            alpha = np.asarray(trial.act(prober.trust_input(k, prober.probe(k, tiled, x, padded))), dtype=np.float64)
            return torch.as_tensor(np.clip(alpha[pick], 0.0, 1.0)[:len(p)])

        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed + k)
            attr = ShapleyValueSampling(forward).attribute(
                torch.as_tensor(x), baselines=torch.as_tensor(xb), feature_mask=mask, n_samples=n_samples,
                perturbations_per_eval=N_GROUPS).numpy()
        base_trust[k] = forward(torch.as_tensor(xb)).numpy()
        # the shadow and the method itself step on the recorded inputs
        inp = episode.input(k)
        method_trust[k] = np.clip(np.asarray(main.act(inp), dtype=np.float64), 0.0, 1.0)
        shadow_alpha = np.clip(np.asarray(shadow.act(prober.trust_input(k, tiled)), dtype=np.float64), 0.0, 1.0)
        trust[k] = shadow_alpha[pick][:m]
        batch_gap = max(batch_gap, float(np.abs(shadow_alpha[pick] - np.tile(method_trust[k][rows], N_GROUPS)).max()))
        values[k] = _spread_groups(attr, x, xb)
    values = values.reshape(n_t * m, n_f)
    trust, base_trust = trust.reshape(-1), base_trust.reshape(-1)
    delta = values.sum(axis=1) - (trust - base_trust)
    return ShapleyResult(values=values, trust=trust, baseline_trust=base_trust, delta=delta,
                         method_trust=method_trust, batch_gap=batch_gap)


def _spread_groups(attr: np.ndarray, x: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """Captum gives every column of a group the group's value; keep it once, on the columns that moved.

    A group's value is split over its columns in proportion to |x − x̄| (a group whose
    columns all equal the baseline is a dummy player: its value is 0).
    """
    out = np.zeros_like(attr)
    for cols in FEATURE_GROUPS.values():
        cols = list(cols)
        if len(cols) == 1:
            out[:, cols[0]] = attr[:, cols[0]]
            continue
        moved = np.abs(x[:, cols] - xb[:, cols])
        total = moved.sum(axis=1, keepdims=True)
        share = np.divide(moved, total, out=np.zeros_like(moved), where=total > 0)
        out[:, cols] = attr[:, [cols[0]]] * share
    return out
