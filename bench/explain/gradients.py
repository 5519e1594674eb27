"""Integrated gradients (Captum) for torch link-trust policies.

A torch policy is explained through a *differentiable form*: a torch function that
gives one channel's trust α from that channel's features x ``(F,)``, the other channels
of its UAV held at their recorded values, and the method's internal state at that step.
:func:`differentiable` builds it for

* ``MappoPolicy`` (the ``ChannelActor``: its per-UAV context is recomputed from the
  channel's block with x in place, so x reaches α through the context too);
* ``MarkovSmoothing`` around a stateless differentiable policy (madrl eq. 15–17; its
  memory — α_eff(k − 1) and r(k − 1) — is state, held at its value on the recorded path,
  as the model-agnostic explainer holds it: the wrapped actor still reads the
  previous-trust feature);
* any policy with a ``torch_trust(obs)`` method mapping one UAV's channels
  ``(..., L, F)`` to trust ``(..., L)`` (the hook for user torch policies; stateless).

Binary switches (valid, the kind one-hot, MAPPO's "kinds it was trained on") enter
multilinearly, so the form equals the method at every recorded input and is smooth
between a baseline and it. Integrated gradients (Sundararajan et al. 2017) then give
attributions that add up to α(x) − α(x̄); Captum reports the gap (the convergence delta)
and rows whose gap exceeds ``tol`` are integrated again with four times the steps.
The form runs in float32; ``attribute`` checks it against the method's own ``act`` on the
recorded inputs.
"""

from __future__ import annotations

import abc
import copy
from dataclasses import dataclass

import numpy as np
import torch
from captum.attr import IntegratedGradients

from swarmloc.agents.mappo.policy import LOGIT_LIMIT, MappoPolicy, channel_context
from swarmloc.agents.protocols import TrustInput
from swarmloc.agents.trust.smoothing import MarkovSmoothing
from swarmloc.envs.tasks.channels import N_KINDS
from swarmloc.envs.world.observation import INNOVATION, KIND0, SCALE_INNOVATION, VALID

from swarmloc.bench.explain.episode import Episode

Tensor = torch.Tensor
#: the forms run in float32, as the actor was trained (float64 halves the speed for no gain at a 1e-5 gap)
DTYPE = torch.float32


class DifferentiableTrust(abc.ABC):
    """One channel's trust as a torch function of its features (see the module docstring).

    ``channel_trust(x, block, slot, state)``: x ``(M, F)`` the channel's features, block
    ``(M, L, F)`` its UAV's recorded channels, slot ``(M,)`` the channel's index in the
    block, state ``(M, S)`` the method's state before the step → α ``(M,)``.
    """

    #: S, the width of the state
    state_size = 0

    def reset(self, batch_size: int, shape: tuple[int, int]) -> None:
        """Start B episodes with N UAVs and L channels."""

    @abc.abstractmethod
    def state(self) -> np.ndarray:
        """``(B, N, L, S)`` state before the pending step."""

    def observe(self, inp: TrustInput, trust: np.ndarray) -> None:
        """Advance the state past a step the method was given and the trust ``(B, N, L)`` it returned."""

    @abc.abstractmethod
    def channel_trust(self, x: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        """α ``(M,)`` of the channels ``x`` (see the class docstring)."""

    def path_kinks(self, x: Tensor, xb: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        """``(M, K)`` points a ∈ [0, 1] of the path x̄ + a (x − x̄) where the gradient may jump
        (1.0 pads); between them the form is smooth. Default: none known."""
        return x.new_zeros((x.shape[0], 0))


def _in_block(x: Tensor, block: Tensor, slot: Tensor) -> Tensor:
    """The block with row ``slot`` replaced by x, differentiably in x."""
    full = block.clone()
    full[torch.arange(x.shape[0]), slot] = x
    return full


class _Stateless(DifferentiableTrust):
    def reset(self, batch_size: int, shape: tuple[int, int]) -> None:
        self._shape = (batch_size, *shape)

    def state(self) -> np.ndarray:
        return np.zeros((*self._shape, 0))


class ActorTrust(_Stateless):
    """``MappoPolicy``: α = d·sigmoid(μ(x, context)) + (1 − d), d = valid · [kind trained on]."""

    def __init__(self, policy: MappoPolicy) -> None:
        self.actor = copy.deepcopy(policy.actor).to(DTYPE).eval()
        for p in self.actor.parameters():
            p.requires_grad_(False)
        self.kinds = torch.tensor(policy.kinds, dtype=DTYPE)
        self.isolation = policy.isolation

    def channel_trust(self, x: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        if not self.isolation:  # trust fixed at 1: a constant that still belongs to the graph
            return x[:, 0] * 0.0 + 1.0
        rows = torch.arange(x.shape[0])
        features = x
        if bool(self.actor.context):
            features = torch.cat([x, channel_context(_in_block(x, block, slot))[rows, slot]], dim=-1)
        raw = self.actor.body(features).squeeze(-1)
        # μ = c · tanh(raw / c), α_raw = sigmoid(μ) (ChannelActor.forward / .trust)
        alpha = torch.sigmoid(LOGIT_LIMIT * torch.tanh(raw / LOGIT_LIMIT))
        decided = x[:, VALID] * (x[:, KIND0:KIND0 + N_KINDS] @ self.kinds)
        return decided * alpha + (1.0 - decided)

    def _network_input(self, xs: Tensor, block: Tensor, slot: Tensor) -> Tensor:
        """Network input ``(M, P, F + C)`` at P path points per row (``xs`` ``(M, P, F)``)."""
        if not bool(self.actor.context):
            return xs
        m, p, f = xs.shape
        flat = xs.reshape(m * p, f)
        blk = block[:, None].expand(m, p, *block.shape[1:]).reshape(m * p, *block.shape[1:])
        sl = slot[:, None].expand(m, p).reshape(-1)
        ctx = channel_context(_in_block(flat, blk, sl))[torch.arange(m * p), sl]
        return torch.cat([flat, ctx], dim=-1).reshape(m, p, -1)

    def path_kinks(self, x: Tensor, xb: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        """Where a ReLU of the actor switches along the path, layer by layer.

        The network input is taken affine along the path (exact for the ``nominal``
        baseline, whose valid flag does not move; a close approximation for ``zeros``).
        Between two consecutive kinks of the layers below, a ReLU's pre-activation is then
        affine too, so its zero crossing is found by linear interpolation. Points are kept
        flat, (row, a) sorted, so rows with few kinks cost little.
        """
        m = x.shape[0]
        if not self.isolation:
            return x.new_zeros((m, 0))
        z0 = self._network_input(xb[:, None], block, slot)[:, 0]
        dz = self._network_input(x[:, None], block, slot)[:, 0] - z0
        rows = torch.arange(m).repeat_interleave(2)
        a = x.new_tensor([0.0, 1.0]).repeat(m)
        layers = list(self.actor.body)
        for depth, layer in enumerate(layers):
            if not isinstance(layer, torch.nn.ReLU):
                continue
            h = torch.nn.Sequential(*layers[:depth])(z0[rows] + a[:, None] * dz[rows])  # (K, H) pre-activations
            same = rows[1:] == rows[:-1]
            lo, hi, a_lo, a_hi = h[:-1][same], h[1:][same], a[:-1][same], a[1:][same]
            pair, unit = torch.nonzero((lo > 0) != (hi > 0), as_tuple=True)
            h_lo, h_hi = lo[pair, unit], hi[pair, unit]
            crossing = a_lo[pair] + (a_hi[pair] - a_lo[pair]) * h_lo / (h_lo - h_hi)
            rows = torch.cat([rows, rows[:-1][same][pair]])
            a = torch.cat([a, crossing.clamp(0.0, 1.0)])
            order = torch.argsort(rows.double() * 2.0 + a.double())
            rows, a = rows[order], a[order]
            keep = torch.cat([torch.ones(1, dtype=torch.bool), (rows[1:] != rows[:-1]) | (a[1:] > a[:-1])])
            rows, a = rows[keep], a[keep]
        inner = (a > 0.0) & (a < 1.0)
        rows, a = rows[inner], a[inner]
        counts = torch.bincount(rows, minlength=m)
        out = x.new_ones((m, int(counts.max()) if len(rows) else 0))
        starts = torch.cumsum(counts, 0) - counts
        out[rows, torch.arange(len(rows)) - starts[rows]] = a
        return out


class HookTrust(_Stateless):
    """A policy with ``torch_trust(obs (..., L, F)) -> (..., L)``."""

    def __init__(self, policy: object) -> None:
        self.policy = policy

    def channel_trust(self, x: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        out = self.policy.torch_trust(_in_block(x, block, slot))  # type: ignore[attr-defined]
        return out[torch.arange(x.shape[0]), slot]


class SmoothedTrust(DifferentiableTrust):
    """``MarkovSmoothing``: α_eff = v (β α_eff(k − 1) + (1 − β) α_raw) + (1 − v) α_eff(k − 1).

    β = β_max exp(−γ |r − r(k − 1)|) with r = unsquash(innovation feature). The state is
    [r(k − 1), α_eff(k − 1)]: the innovation of the channel's last present measurement
    (0 at the start) and the smoother's last output (1 at the start), as the smoother
    itself keeps them.
    """

    state_size = 2

    def __init__(self, smoother: MarkovSmoothing, inner: DifferentiableTrust) -> None:
        self.beta_max, self.gamma = smoother.beta_max, smoother.gamma
        self.inner = inner

    def reset(self, batch_size: int, shape: tuple[int, int]) -> None:
        self.inner.reset(batch_size, shape)
        self._resid = np.zeros((batch_size, *shape))
        self._alpha = np.ones((batch_size, *shape))

    def state(self) -> np.ndarray:
        return np.stack([self._resid, self._alpha], axis=-1)

    def observe(self, inp: TrustInput, trust: np.ndarray) -> None:
        self._resid = np.where(inp.valid, inp.resid, self._resid)
        self._alpha = np.asarray(trust, dtype=np.float64).copy()

    def channel_trust(self, x: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        raw = self.inner.channel_trust(x, block, slot, state[:, 2:]).clamp(0.0, 1.0)
        y = x[:, INNOVATION]
        resid = SCALE_INNOVATION * y / (1.0 - y).clamp(min=1e-12)  # unsquash
        # β = β_max exp(−γ |r(k) − r(k−1)|);  α_eff = β α_eff(k−1) + (1 − β) α_raw
        beta = self.beta_max * torch.exp(-self.gamma * (resid - state[:, 0]).abs())
        alpha_prev = state[:, 1]
        valid = x[:, VALID]
        return valid * (beta * alpha_prev + (1.0 - beta) * raw) + (1.0 - valid) * alpha_prev

    def path_kinks(self, x: Tensor, xb: Tensor, block: Tensor, slot: Tensor, state: Tensor) -> Tensor:
        """The wrapped policy's kinks and where |r − r(k − 1)| changes sign (r is monotone in a)."""
        inner = self.inner.path_kinks(x, xb, block, slot, state[:, 2:])
        y, yb = x[:, INNOVATION], xb[:, INNOVATION]
        y_star = state[:, 0] / (state[:, 0] + SCALE_INNOVATION)  # squash(r(k − 1))
        moves = y != yb
        a = torch.where(moves, (y_star - yb) / torch.where(moves, y - yb, torch.ones_like(y)), torch.ones_like(y))
        a = torch.where((a > 0.0) & (a < 1.0), a, torch.ones_like(a))
        return torch.cat([inner, a[:, None]], dim=1)


def differentiable(method: object) -> DifferentiableTrust | None:
    """The differentiable form of a Track A method, or None when it has none (then use Shapley sampling)."""
    if isinstance(method, MarkovSmoothing):
        inner = differentiable(method.policy)
        # the smoother's memory is the outer output; a stateful inner form would need its own
        return None if inner is None or inner.state_size else SmoothedTrust(method, inner)
    if isinstance(method, MappoPolicy):
        return ActorTrust(method)
    if callable(getattr(method, "torch_trust", None)):
        return HookTrust(method)
    return None


@dataclass(frozen=True)
class GradientResult:
    """Integrated gradients of the explained rows.

    Attributes:
        values: ``(R, F)`` attributions.
        trust, baseline_trust: ``(R,)`` α(x) and α(x̄) of the differentiable form.
        delta: ``(R,)`` Σ attributions − (α(x) − α(x̄)) (the completeness gap).
        n_evals: ``(R,)`` gradient evaluations each row took.
    """

    values: np.ndarray
    trust: np.ndarray
    baseline_trust: np.ndarray
    delta: np.ndarray
    n_evals: np.ndarray


def _rows(form: DifferentiableTrust, episode: Episode, explained: np.ndarray, own_trust: np.ndarray):
    """Per explained (step, episode, UAV, channel) row: x, its UAV block, slot and state."""
    n_b, n, n_l = episode.obs.shape[1:4]
    form.reset(n_b, (n, n_l))
    b_idx, n_idx, l_idx = np.nonzero(np.broadcast_to(explained, (n_b, n, n_l)))
    xs, blocks, states = [], [], []
    for k in range(episode.n_steps):
        obs = episode.obs[k].astype(np.float64)
        xs.append(obs[b_idx, n_idx, l_idx])
        blocks.append(obs[b_idx, n_idx])
        states.append(form.state()[b_idx, n_idx, l_idx])
        form.observe(episode.input(k), own_trust[k])
    slot = np.tile(l_idx, episode.n_steps)
    return np.concatenate(xs), np.concatenate(blocks), slot, np.concatenate(states)


def _row_gradients(forward_fn, inputs, target_ind=None, additional_forward_args=None) -> tuple[Tensor, ...]:
    """Captum's ``gradient_func`` for row-wise forwards: ∂(Σ_m α_m)/∂x = ∂α_m/∂x_m row by row.

    Every output depends on its own row only, so one backward pass of the sum gives all
    the per-row gradients; Captum's default differentiates each of the M·steps scalars
    separately, which costs more than the network itself at this size.
    """
    with torch.autograd.set_grad_enabled(True):
        args = additional_forward_args if isinstance(additional_forward_args, tuple) else ()
        outputs = forward_fn(*inputs, *args)
        return torch.autograd.grad(outputs.sum(), inputs)


def _segments(points: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(row, start, end) of every non-empty segment between a row's sorted path points."""
    lo, hi = points[:, :-1], points[:, 1:]
    row, seg = torch.nonzero(hi > lo, as_tuple=True)
    return row, lo[row, seg], hi[row, seg]


def integrated_gradients(form: DifferentiableTrust, episode: Episode, baseline: np.ndarray, explained: np.ndarray,
                         own_trust: np.ndarray, n_steps: int = 4, tol: float = 2e-5, max_steps: int = 64,
                         chunk: int = 512) -> GradientResult:
    """Integrated gradients of every explained channel at every step of a recorded episode.

    The straight path x̄ → x is cut at the form's kinks (:meth:`DifferentiableTrust.path_kinks`:
    ReLU switches, |Δr| = 0), where the gradient jumps; on each piece, where the form is
    smooth, Captum integrates with ``n_steps`` Gauss–Legendre nodes, and the pieces add up
    (IG is additive along a path). Rows whose completeness gap still exceeds ``tol`` are
    integrated again with 4× the nodes, up to ``max_steps``.

    Args:
        form: the method's differentiable form (:func:`differentiable`).
        episode: the recorded inputs.
        baseline: ``(T, B, N, L, F)`` baseline features x̄.
        explained: ``(N, L)`` bool, the channels to explain (of every UAV and episode).
        own_trust: ``(T, B, N, L)`` the method's own trust on the recorded inputs (its state).
        n_steps: Gauss–Legendre nodes per smooth piece of the first pass.
        tol: completeness gap that sends a row to another pass …
        max_steps: … with 4× the nodes per piece, up to this many.
        chunk: rows per batch of kink search and integration.

    Returns:
        The ``GradientResult`` of the rows in (step, episode, UAV, channel) order.
    """
    x, block, slot, state = _rows(form, episode, explained, own_trust)
    n_b, n, n_l = episode.obs.shape[1:4]
    b_idx, n_idx, l_idx = np.nonzero(np.broadcast_to(explained, (n_b, n, n_l)))
    xb = baseline[:, b_idx, n_idx, l_idx].reshape(-1, x.shape[1])
    t = lambda a, dt=DTYPE: torch.as_tensor(a, dtype=dt)
    ig = IntegratedGradients(form.channel_trust)
    ig.gradient_func = _row_gradients
    values = np.zeros_like(x)
    with torch.no_grad():
        trust = form.channel_trust(t(x), t(block), t(slot, torch.long), t(state)).numpy()
        base_trust = form.channel_trust(t(xb), t(block), t(slot, torch.long), t(state)).numpy()
    # rows already at their baseline have zero attribution: no path to integrate
    todo = np.nonzero(np.any(x != xb, axis=1))[0]
    n_evals = np.zeros(len(x), dtype=np.int64)
    steps = n_steps
    while len(todo) and steps <= max_steps:
        for start in range(0, len(todo), chunk):
            idx = todo[start:start + chunk]
            xi, bi, blk, sl, st = t(x[idx]), t(xb[idx]), t(block[idx]), t(slot[idx], torch.long), t(state[idx])
            with torch.no_grad():
                kinks = form.path_kinks(xi, bi, blk, sl, st)
            ends = torch.zeros(len(idx), 1, dtype=xi.dtype), torch.ones(len(idx), 1, dtype=xi.dtype)
            points = torch.sort(torch.cat([ends[0], kinks.clamp(0.0, 1.0), ends[1]], dim=1), dim=1).values
            row, a_lo, a_hi = _segments(points)
            d = xi - bi
            seg_in, seg_base = bi[row] + a_hi[:, None] * d[row], bi[row] + a_lo[:, None] * d[row]
            attr = ig.attribute(seg_in, baselines=seg_base, additional_forward_args=(blk[row], sl[row], st[row]),
                                n_steps=steps, method="gausslegendre")
            total = torch.zeros_like(xi).index_add_(0, row, attr)
            values[idx] = total.numpy()
            n_evals[idx] = steps * torch.bincount(row, minlength=len(idx)).numpy()
        gap = values.sum(axis=1) - (trust - base_trust)
        todo = todo[np.abs(gap[todo]) > tol]
        steps *= 4
    delta = values.sum(axis=1) - (trust - base_trust)
    return GradientResult(values=values, trust=trust, baseline_trust=base_trust, delta=delta, n_evals=n_evals)
