"""Compute cost model: analytic filter FLOPs and the processor profile.

The standard reward's delay and energy terms convert FLOPs into time and joules on a
stated embedded processor. FLOPs are counted analytically from what the CEKF kernel
executes (see ``cekf.py``): a fixed prediction cost plus a cost per scalar row of the
joint update, so skipping a channel (α ≤ α_th) saves its rows.
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmloc.envs.filter.constants import SPLIT_CI_GRID, SPLIT_CI_STEPS, SPLIT_CI_WARM_STEPS

#: prediction of one UAV: x⁻ = F x + G u (18), block F P Fᵀ (63), Q (36), constants (2)
PREDICT_FLOPS = 119
#: one range row: model h, ‖·‖ and H (12), y (10), c = P Hᵀ (30), s (6), gain (2),
#: x += k y (12), symmetric P − c cᵀ/s on 21 entries (63)
RANGE_ROW_FLOPS = 135
#: one row of a 3-vector channel (GPS, landmark, relative position): y (3), s (1),
#: gain (2), x (12), P (63)
VECTOR_ROW_FLOPS = 81
#: one TDOA row: a range row whose model is two ranges, ‖p − a_j‖ − ‖p − a_i‖, and whose
#: H is the difference of the two unit vectors: 2 × 12 + 4 in place of the range's 12
TDOA_ROW_FLOPS = RANGE_ROW_FLOPS - 12 + 28
#: covariance intersection (``FilterSettings.peer_update = "ci"``), on top of the rows above:
#: a peer range adds hᵀP_j h and tr (24), the ω search (49 × 8) and P/ω on 36 entries
CI_RANGE_FLOPS = 24 + 49 * 8 + 36
#: a relative-position link updates as one 3-row block: the ω search (49 × (3×3 S and its
#: inverse 45, tr(A S⁻¹ A) 54)), then the gain (90), x (18), P (126) and P/ω (36)
CI_REL_FLOPS = 49 * 99 + 90 + 18 + 126 + 36
#: split covariance intersection (``FilterSettings.peer_update = "split_ci"``, ``envs/filter/split_ci.py``):
#: the independent part's prediction F N Fᵀ + Q, per UAV-step
SPLIT_PREDICT_FLOPS = 63 + 36
#: per absolute row: the gain k = c / s (8), then both independent parts through it: M Hᵀ and
#: H M Hᵀ (23) and the symmetric update of 21 entries (7 each), twice
SPLIT_TRACK_ROW_FLOPS = 8 + 2 * (23 + 21 * 7)
#: a symmetric positive definite 6×6 inverse by Cholesky: the factor (91 with 6 roots), L⁻¹ (76), L⁻ᵀ L⁻¹ (182)
SPD6_INVERSE_FLOPS = 91 + 76 + 182
#: one evaluation of the weight search's tr P⁺ (``split_ci._fused_trace``) without its peers, in 3×3 form:
#: I + P1_pp M (117), AᵀA (36), its determinant (17) and inverse (41), X = M (I + P1_pp M)⁻¹ (45), the
#: trace (21); its gradient: Q_pp = B AᵀA Bᵀ (90), tr(Z D' Zᵀ) (702), 3
SPLIT_CI_EVAL_FLOPS = 117 + 36 + 17 + 41 + 45 + 21
SPLIT_CI_GRAD_FLOPS = 90 + 702 + 3
#: once per UAV-step with peers: N' = N_old + N_new (36), the weight-free parts of tr P⁺ (``_prepare``,
#: 560), the grid of ω_0 (SPLIT_CI_GRID − 1 evaluations), the multiplicative steps (SPLIT_CI_STEPS
#: evaluations with their gradients and steps, 4 per source, then one more evaluation), the comparison
#: with no update (6), P1 = D'/ω + N' (108)
SPLIT_CI_FLOPS = (36 + 560 + (SPLIT_CI_GRID + SPLIT_CI_STEPS) * SPLIT_CI_EVAL_FLOPS
                  + SPLIT_CI_STEPS * (SPLIT_CI_GRAD_FLOPS + 4) + 6 + 108)
#: per peer range: the model and u (12), uᵀD_j u, uᵀN_j u and P u (60), its share (6), each evaluation
#: (R_j 3, the rank-one term 27), each gradient (R_j 3, uᵀQu 36, 5) and step (4), its row (the range
#: row's 135 + R_j 3) and N_new through it (8 + 23 + 21 × 7)
SPLIT_CI_RANGE_FLOPS = (12 + 60 + 6 + (SPLIT_CI_GRID + SPLIT_CI_STEPS) * 30 + SPLIT_CI_STEPS * (44 + 4)
                        + 135 + 3 + 8 + 23 + 21 * 7)
#: per relative position: its share (S 12, inverse 45, tr(A S⁻¹ A) 54), each evaluation (R_j 36,
#: inverse 45, sum 9), each gradient (R_j and its inverse 81, R_j⁻¹ D_j R_j⁻¹ 99, a trace 18, 2) and
#: step (4), the 3-row block (S 36, inverse 45, gain 90, x 18, P 126) and N_new through it (21 × 45)
SPLIT_CI_REL_FLOPS = (12 + 45 + 54 + (SPLIT_CI_GRID + SPLIT_CI_STEPS) * 90 + SPLIT_CI_STEPS * (200 + 4)
                      + 36 + 45 + 90 + 18 + 126 + 21 * 45)
#: the same after a warm start (the previous update's weights, mixed with the shares: 4 per source, 1 to
#: normalise): SPLIT_CI_WARM_STEPS evaluations with their gradients and steps, then one more, no grid
SPLIT_CI_WARM_FLOPS = (36 + 560 + 2 + (SPLIT_CI_WARM_STEPS + 1) * SPLIT_CI_EVAL_FLOPS
                       + SPLIT_CI_WARM_STEPS * (SPLIT_CI_GRAD_FLOPS + 4) + 6 + 108)
SPLIT_CI_WARM_RANGE_FLOPS = (12 + 60 + 6 + 5 + (SPLIT_CI_WARM_STEPS + 1) * 30 + SPLIT_CI_WARM_STEPS * (44 + 4)
                             + 135 + 3 + 8 + 23 + 21 * 7)
SPLIT_CI_WARM_REL_FLOPS = (12 + 45 + 54 + 5 + (SPLIT_CI_WARM_STEPS + 1) * 90 + SPLIT_CI_WARM_STEPS * (200 + 4)
                           + 36 + 45 + 90 + 18 + 126 + 21 * 45)


def filter_flops(n_range_rows: np.ndarray, n_vector_rows: np.ndarray, n_tdoa_rows: np.ndarray | int = 0) -> np.ndarray:
    """CEKF FLOPs per UAV-step from the active scalar rows.

    Args:
        n_range_rows: active range rows (anchor and peer channels), any shape.
        n_vector_rows: active rows of 3-vector channels (3 per channel), same shape.
        n_tdoa_rows: active TDOA rows (one per channel), same shape (default none).

    Returns:
        FLOPs, same shape.
    """
    return (PREDICT_FLOPS + RANGE_ROW_FLOPS * np.asarray(n_range_rows) + VECTOR_ROW_FLOPS * np.asarray(n_vector_rows)
            + TDOA_ROW_FLOPS * np.asarray(n_tdoa_rows))


class ProcessorProfile(BaseModel):
    """An embedded processor as the reward sees it: FLOP/s and power.

    ``effective_flops`` is the sustained rate of scalar float32 filter and MLP code, not
    the peak: clock × FLOPs per cycle actually achieved.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    version: int = Field(ge=0)
    clock_hz: float = Field(gt=0)
    flops_per_cycle: float = Field(gt=0)
    power_w: float = Field(gt=0)
    description: str = ""

    @property
    def effective_flops(self) -> float:
        """Sustained FLOP/s = clock × FLOPs per cycle."""
        return self.clock_hz * self.flops_per_cycle

    def seconds(self, flops: np.ndarray | float) -> np.ndarray:
        """Execution time [s] of ``flops`` on this processor."""
        return np.asarray(flops, dtype=float) / self.effective_flops

    def joules(self, flops: np.ndarray | float) -> np.ndarray:
        """Energy [J] of ``flops``: time × active power."""
        return self.seconds(flops) * self.power_w


#: Default profile (v0): an STM32F427-class Cortex-M4F flight controller (Crazyflie 2.x,
#: Pixhawk 1). 180 MHz; the single-precision FPU issues one FLOP per cycle at best, and
#: scalar filter / MLP code with loads and stores sustains about a quarter of that;
#: run-mode supply ≈ 100 mA at 3.3 V.
STM32F427_V0 = ProcessorProfile(
    name="stm32f427-cortex-m4f",
    version=0,
    clock_hz=180e6,
    flops_per_cycle=0.25,
    power_w=0.33,
    description="STM32F427 Cortex-M4F @180 MHz, 0.25 sustained FLOP/cycle (45 MFLOP/s), 0.33 W active",
)
DEFAULT_PROFILE = STM32F427_V0
