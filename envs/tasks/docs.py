"""Composes the Gymnasium-style class docstring of a task from its spec.

Each per-task class (``adapters/task_envs.py``) brings its own Description and Version History;
everything that follows from the spec — channel layout, measurement model, reward
constants, episode length, shapes, argument table and a doctest — is generated here so it
cannot drift from the numbers the environment actually uses. ``docgen`` turns the
resulting ``__doc__`` into ``docs/tasks/<Name>.md`` (``swarmloc docs tasks``).
"""

from __future__ import annotations

import math

from swarmloc.envs.tasks.channels import KIND_NAMES, build_layout
from swarmloc.envs.world.cost import DEFAULT_PROFILE
from swarmloc.envs.world.observation import FEATURE_NAMES, SCALE_DISTANCE, SCALE_INNOVATION, SCALE_JERK, SCALE_NIS
from swarmloc.envs.world.reward import REWARD_VERSION, STANDARD_WEIGHTS
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec

#: the sections every task docstring has, in order (a test checks them)
SECTIONS = ("Description", "Action Space", "Observation Space", "Rewards", "Starting State", "Episode End",
            "Arguments", "Measurement Model", "Batch Shapes", "Version History")

_FEATURE_ROWS = (
    ("innovation magnitude ‖y‖ at the prior, squashed r/(r+{s_i:g} m)", "0", "1"),
    ("predicted distance ‖h(x⁻)‖ to the channel's target, squashed d/(d+{s_d:g} m); 0 for GPS", "0", "1"),
    ("trust applied to this channel at the previous update", "0", "1"),
    ("the UAV's IMU jerk ‖u(k) − u(k−1)‖, squashed j/(j+{s_j:g} m/s²)", "0", "1"),
    ("normalised innovation squared yᵀS⁻¹y (S with nominal R0), squashed ν/(ν+{s_n:g})", "0", "1"),
    ("kind one-hot: anchor range, or TDOA range difference of an anchor pair", "0", "1"),
    ("kind one-hot: peer range", "0", "1"),
    ("kind one-hot: landmark (camera, 3-vector)", "0", "1"),
    ("kind one-hot: GPS fix (3-vector)", "0", "1"),
    ("kind one-hot: peer relative position (3-vector)", "0", "1"),
    ("valid: 1 if the channel carries a measurement this step", "0", "1"),
)


def _channel_slots(spec: TaskSpec) -> str:
    layout = build_layout(spec)
    kinds = layout.kind[0]
    parts, start = [], 0
    for col in range(1, len(kinds) + 1):
        if col == len(kinds) or kinds[col] != kinds[start]:
            name = KIND_NAMES[kinds[start]]
            span = f"{start}" if col - start == 1 else f"{start}–{col - 1}"
            parts.append(f"{span}: {name}")
            start = col
    text = "; ".join(parts)
    if spec.n_peer_channels:
        text += " (peer slots list the other UAVs in index order)"
    return text


def _faults(spec: TaskSpec) -> list[str]:
    f, lines = spec.faults, []
    for s in f.nlos_steps:
        nodes = f"UAVs {list(s.nodes)}" if s.nodes else "every UAV"
        lines.append(f"NLOS step: +{s.bias:g} m on {s.target} {s.index} seen by {nodes}, {s.start:g}–{s.end:g} s.")
    if (g := f.nlos_gauss_markov) is not None:
        nodes = f"UAVs {list(g.nodes)}" if g.nodes else "every UAV"
        links = "/".join("TDOA pair (the second anchor delayed: +bias)" if t == "anchor" and spec.sensors.tdoa
                         else t for t in g.targets)
        lines.append(f"Random NLOS on {links} links of {nodes}: onset rate {g.onset_rate:g}/s, "
                     f"mean episode {g.mean_duration:g} s; bias Gauss–Markov around {g.mean_bias:g} m "
                     f"(σ {g.bias_sigma:g} m, τ {g.tau:g} s) clipped to [0, {g.max_bias:g}] m.")
    if (u := f.nlos_uniform) is not None:
        lines.append(f"NLOS windows {list(u.windows)} s on {'/'.join(u.targets)} links ({u.link_fraction:.0%} of "
                     f"links): bias uniform in [{u.low:g}, {u.high:g}] m per measurement.")
    for c in f.imu_cascades:
        blind = "; they receive no measurement inside the window (blind dead reckoning)" if c.blind else ""
        lines.append(f"IMU bias {list(c.bias)} m/s² on UAVs {list(c.nodes)}, {c.start:g}–{c.end:g} s{blind}.")
    if (r := f.imu_cascade_random) is not None:
        lines.append(f"Random IMU cascade: {r.n_faulty} UAVs drawn per episode, start uniform in "
                     f"{list(r.start_range)} s, duration in {list(r.duration_range)} s, bias magnitude in "
                     f"{list(r.bias_magnitude_range)} m/s²{', blind inside the window' if r.blind else ''}.")
    if (v := f.vision_outage) is not None:
        lines.append(f"Camera outages {list(v.windows)} s: no landmark channel is valid.")
    if (vr := f.vision_outage_random) is not None:
        nodes = f"UAVs {list(vr.nodes)}" if vr.nodes else "every UAV"
        lines.append(f"Random camera outages on {nodes}: {vr.count_range[0]}–{vr.count_range[1]} per episode, "
                     f"each lasting {vr.duration_range[0]:g}–{vr.duration_range[1]:g} s, one per equal slot of "
                     f"{vr.span[0]:g}–{vr.span[1]:g} s (drawn per episode); no landmark channel is valid inside.")
    if f.packet_loss:
        lines.append(f"UWB packet loss {f.packet_loss:.0%}.")
    if (o := f.uwb_outage) is not None:
        nodes = f"UAVs {list(o.nodes)}" if o.nodes else "every UAV"
        lines.append(f"UWB loss {list(o.windows)} s: {'/'.join(o.targets)} ranges lost on {nodes}.")
    for d in f.gps_drifts:
        lines.append(f"GPS drift {d.rate:g} m/s along {list(d.direction)} on UAVs {list(d.nodes)}, "
                     f"{d.start:g}–{d.end:g} s.")
    if (dr := f.gps_drift_random) is not None:
        k = dr.n_drifting_range
        lines.append(f"Random GPS drift (drawn per episode): {k[0]}–{k[1]} of UAVs {list(dr.nodes)} drift alike "
                     f"from a start in {list(dr.start_range)} s for {list(dr.duration_range)} s at "
                     f"{dr.rate_range[0]:g}–{dr.rate_range[1]:g} m/s, {dr.elevation_deg:.3g}° above the horizontal "
                     "with a uniform azimuth; the offset stays after the window.")
    if (h := f.hybrid_noise) is not None:
        r = h.ratio_range
        ratio = f"{h.ratio:g}" if r is None else f"drawn per episode uniform in [{r[0]:g}, {r[1]:g}]"
        if h.model == "mixture":
            lines.append(f"Hybrid GPS noise on UAVs {list(h.nodes) or 'all'}, a contamination mixture: each fix is "
                         f"Student-t (scale {h.t_scale:g} m, ν ∈ [{h.dof_low}, {h.dof_high}]) with probability "
                         f"{ratio}, else N(0, {h.gauss_sigma:g}² I).")
        else:
            lines.append(f"Hybrid GPS noise on UAVs {list(h.nodes) or 'all'}: v = a·t_ν(σ {h.t_scale:g}) + "
                         f"(1 − a)·N(0, {h.gauss_sigma:g}²), a = {ratio}, ν ∈ [{h.dof_low}, {h.dof_high}].")
    lines += [f"{name}: {value}." for name, value in _other_fields(f, _DESCRIBED_FAULTS)]
    return lines or ["None: Gaussian noise only."]


_DESCRIBED_FAULTS = {"nlos_steps", "nlos_gauss_markov", "nlos_uniform", "imu_cascades", "imu_cascade_random",
                     "vision_outage", "packet_loss", "gps_drifts", "hybrid_noise", "uwb_outage",
                     "vision_outage_random", "gps_drift_random"}
_DESCRIBED_SENSORS = {"imu_sigma", "imu_bias_sigma", "anchor_sigma", "anchor_max_range", "peers", "camera_sigma",
                      "camera_max_range", "gps_sigma", "gps_nodes", "gps_correlation_time", "velocity_sigma",
                      "velocity_bias_sigma", "tdoa"}


def _other_fields(model, described: set[str]) -> list[tuple[str, object]]:
    """Fields of ``model`` set away from their default that the text above does not describe."""
    defaults = type(model)()
    return [(name, getattr(model, name)) for name in type(model).model_fields
            if name not in described and getattr(model, name) != getattr(defaults, name)]


def _gps_line(spec: TaskSpec) -> str:
    """The Measurement Model's GPS line: the receivers, σ and, where correlated, the error's time constant."""
    s = spec.sensors
    if s.gps_nodes:
        without = [i for i in range(spec.n_uav) if i not in s.gps_nodes]
        who = (f"position fix on UAVs {sorted(s.gps_nodes)} (a GNSS receiver; the GPS slots of UAVs {without} "
               "are never valid)")
    else:
        who = "position fix per UAV"
    line = f"- GPS: {who}, σ = {list(s.gps_sigma)} m"
    if s.gps_correlation_time > 0:
        phi = math.exp(-spec.dt / s.gps_correlation_time)
        line += (f"; the error of each axis is Gauss–Markov in time, τ = {s.gps_correlation_time:g} s (stationary "
                 f"std σ, lag-1 autocorrelation exp(−dt/τ) = {phi:.3g}), nominal noise, not a fault")
    return line + "."


def _measurement_model(spec: TaskSpec) -> str:
    s, recorded = spec.sensors, spec.trajectory.kind == "recorded"
    params = ', '.join(f'{k}={v}' for k, v in spec.trajectory.model_dump().items() if k != 'kind')
    truth = f"recorded flight, replayed ({params}); truth is the motion-capture track" if recorded \
        else f"`{spec.trajectory.kind}` trajectories ({params})"
    imu = (f"the logged accelerometer rotated into the world frame by an `imufusion` AHRS (gyro + "
           f"accelerometer only, heading 0 at power-on; no mocap attitude), gravity removed, averaged over "
           f"each step; process-model σ_imu = {s.imu_sigma:g} m/s² (`swarmloc.envs.recorded.util_flight`)."
           if recorded else f"world-frame accelerometer u = a + b + n, σ_imu = {s.imu_sigma:g} m/s²"
           + (f", constant bias σ {s.imu_bias_sigma:g} m/s²." if s.imu_bias_sigma else "."))
    lines = [f"- Truth: {truth}.", f"- IMU: {imu}"]
    if spec.anchors:
        where = (f"surveyed positions read from the data set (`{spec.trajectory.anchors}`)" if recorded
                 else f"{list(spec.anchors)} m")
        if s.tdoa is None:
            lines.append(f"- Anchors: {len(spec.anchors)} UWB anchors at {where}, range σ {s.anchor_sigma:g} m"
                         + (f", ranged within {s.anchor_max_range:g} m." if s.anchor_max_range < 1e6 else "."))
        else:
            pairs = ", ".join(f"({i}, {j})" for i, j in s.tdoa.pairs)
            lines.append(f"- Anchors: {len(spec.anchors)} UWB anchors at {where}, transmitters only (TDOA: no two-way "
                         f"ranging). Channel (i, j) measures z = ‖p − a_j‖ − ‖p − a_i‖ + v, σ {s.tdoa.sigma:g} m, "
                         f"pairs {pairs}; H = u_j − u_i on the position (u_k the unit vector from anchor k).")
    if spec.n_peer_channels:
        kind = "range" if s.peers.kind == "range" else "relative position (3-vector)"
        leaders = (f" (leaders {list(s.peers.leaders)}: each follower measures every leader, each leader the "
                   "other leaders)" if s.peers.leaders != (0,) else "")
        lines.append(f"- Peers: UWB {kind} to other UAVs, topology `{s.peers.topology}`{leaders}, σ {s.peers.sigma:g} m; "
                     "fused against the neighbour's broadcast prior estimate"
                     + (" by covariance intersection" if spec.filter.peer_update == "ci" else "")
                     + (f"; max range {s.peers.max_range:g} m." if s.peers.max_range < 1e6 else "."))
    if spec.landmarks:
        lines.append(f"- Camera: {len(spec.landmarks)} landmarks, relative position σ {s.camera_sigma:g} m per "
                     f"axis, visible within {s.camera_max_range:g} m.")
    if s.gps_sigma:
        lines.append(_gps_line(spec))
    if s.velocity_sigma is not None:
        lines.append(f"- Visual odometry: world-frame velocity per UAV, σ {s.velocity_sigma:g} m/s per axis"
                     + (f", constant per-episode bias σ {s.velocity_bias_sigma:g} m/s" if s.velocity_bias_sigma
                        else "") + "; Track B estimators receive it as `Measurements.velocity` (the link-trust "
                     "CEKF does not use it).")
    if spec.scoring.align_first_seconds > 0:
        lines.append(f"- Scoring: errors after the yaw + 3-D translation that aligns the estimates of "
                     f"{spec.scoring.start:g}–{spec.scoring.start + spec.scoring.align_first_seconds:g} s with the "
                     "truth (absolute translation and yaw are unobservable; `swarmloc.bench.evaluation.alignment`).")
    if spec.scoring.nodes_from_schedule == "healthy":
        lines.append("- Scoring: each episode scores only the UAVs its fault schedule leaves without an IMU fault "
                     "(`scoring.nodes_from_schedule = \"healthy\"`); how fast the faulty ones get back is "
                     "`recovery_s` (docs/scoring.md).")
    lines += [f"- Sensors, `{name}`: {value}." for name, value in _other_fields(s, _DESCRIBED_SENSORS)]
    fl = spec.filter
    lines.append(f"- Filter: one 6-state CEKF per UAV; a channel joins the joint update when α > α_th = "
                 f"{fl.alpha_th:g}, with R = R0 / max(α, {fl.alpha_min:g}).")
    if recorded and s.tdoa is not None:
        faults = ("Real, not injected: the recording's own NLOS, outliers and dropouts. Range differences larger "
                  "than their anchors' baseline are dropped; a step without an arrival masks the channel. A range "
                  "difference is labelled faulty (the label the detection metrics count) when its residual against "
                  "the truth exceeds 3σ; the values are raw (no calibration: the per-pair offsets of 0.1–0.25 m "
                  "stay).")
    elif recorded:
        faults = ("Real, not injected: the recording's own NLOS and outliers (anchor 6 drifts like NLOS; sparse "
                  "spikes on anchors 1, 3, 7). A range is labelled faulty when it deviates from its anchor's median "
                  "residual against the truth by more than 3 robust spreads; "
                  + (f"the ranges are calibrated per anchor from log `{spec.trajectory.calibration}`."
                     if spec.trajectory.calibration else "the ranges are raw (not calibrated)."))
    else:
        faults = " ".join(_faults(spec))
    lines.append("- Faults: " + faults)
    return "\n    ".join(lines)


def _start(spec: TaskSpec) -> str:
    if spec.trajectory.kind == "recorded":
        return (f"Step 0 is log time {spec.trajectory.start:g} s of the recording `{spec.trajectory.log}` (take-off); "
                "every seed replays the same flight.")
    return "Truth starts at t = 0 on the task's trajectories."


def task_doc(task_id: str, description: str, history: tuple[str, ...]) -> str:
    """The full class docstring of ``task_id``.

    Args:
        task_id: registered ID, e.g. ``"swarmloc/NLOS-v0"``.
        description: the task's own Description paragraph(s) (plain text, may span lines).
        history: Version History lines, oldest first (``"v0: ..."``).

    Returns:
        A docstring with every section in ``SECTIONS`` as ``## <Section>`` headings.
    """
    spec = get_spec(task_id)
    n, n_l, n_f, t = spec.n_uav, spec.n_channels, len(FEATURE_NAMES), spec.n_steps
    w, p = STANDARD_WEIGHTS, DEFAULT_PROFILE
    rows = "\n    ".join(
        f"| {i} | {text.format(s_i=SCALE_INNOVATION, s_d=SCALE_DISTANCE, s_j=SCALE_JERK, s_n=SCALE_NIS)} "
        f"| {lo} | {hi} |" for i, (text, lo, hi) in enumerate(_FEATURE_ROWS))
    desc = "\n    ".join(line.strip() for line in description.strip().splitlines())
    summary, body = desc.splitlines()[0], desc[0].upper() + desc[1:]
    hist = "\n    ".join(f"- {line}" for line in history)
    return f"""{spec.name}: {summary}

    ## Description

    {body}

    ## Action Space

    `Box(0.0, 1.0, ({n}, {n_l}), float32)`: the trust α ∈ [0, 1] of every channel of every
    UAV for the pending update. Channels with α ≤ α_th = {spec.filter.alpha_th:g} are skipped
    (no FLOPs, no energy); the others enter the joint CEKF update with R = R0 / max(α,
    {spec.filter.alpha_min:g}). NaN or ±inf raise `ValueError`; a wrong shape raises
    `ValueError` naming `(N, L) = ({n}, {n_l})`; values outside [0, 1] are clipped with a
    warning (once per environment). Smoothing of α is the method's business, not the env's.

    ## Observation Space

    `Box(0.0, 1.0, ({n}, {n_l}, {n_f}), float32)`: per UAV (axis 0) and channel (axis 1),
    {n_f} features of the pending measurement (axis 2). Channel slots: {_channel_slots(spec)}.
    Absent measurements keep their slot with `valid` = 0 and zero innovation features.

    | Num | Observation | Min | Max |
    |-----|-------------|-----|-----|
    {rows}

    ## Rewards

    Standard reward v{REWARD_VERSION} per UAV: r = R_acc − {w.delay:g}·P_delay − {w.energy:g}·P_energy −
    {w.jitter:g}·P_jitter, with R_acc = exp(−‖p̂ − p‖² / (2·{w.sigma_acc:g}²)); P_delay =
    max(0, exp((t_calc − T_max)/T_max) − 1), T_max = {w.t_max * 1e3:g} ms, t_calc = (filter FLOPs +
    `policy_flops`) / {p.effective_flops / 1e6:g} MFLOP/s ({p.description}); P_energy = fraction
    of valid channels with α > α_th; P_jitter = mean |α(k) − α(k−1)| over valid channels.
    The Gymnasium reward is the team reward, the mean over UAVs; PettingZoo and torchrl give
    each UAV its own. `info` holds every term per UAV (`(N,)` arrays): `uav_reward`,
    `accuracy`, `delay_penalty`, `energy_penalty`, `jitter_penalty`, `flops`, `delay_ms`,
    `energy_j`, and `position_error` ‖p̂ − p‖ [m].

    ## Starting State

    {_start(spec)} Each UAV's prior is the truth
    perturbed by N(0, {spec.filter.init_pos_sigma:g}² m²) per position axis and
    N(0, {spec.filter.init_vel_sigma:g}² m²/s²) per velocity axis, with that diagonal covariance.
    The first observation describes the measurements of step 1 at the predicted prior.
    `reset(seed=s)` plays episode seed `s`; `reset()` draws the next seed from `np_random`.

    ## Episode End

    - Termination: never (`terminated` is always False); localization has no terminal state.
    - Truncation: after {t} updates (duration {spec.duration:g} s / dt {spec.dt:g} s); the
      registration's `max_episode_steps` is {t}. With a `duration`/`dt` override the episode
      ends after min(duration/dt, `max_episode_steps`) updates.

    ## Arguments

    | Argument | Default | Description |
    |----------|---------|-------------|
    | `render_mode` | `None` | `"rgb_array"` (480×480 RGB top-down frame) or `"human"` (window where a display exists) |
    | `reward_weights` | standard v{REWARD_VERSION} | `RewardWeights` or a dict of `delay`, `energy`, `jitter`, `sigma_acc`, `t_max` |
    | `policy_flops` | `0` | FLOPs the method spends per UAV per step, added to the delay and energy terms |
    | `processor` | `{p.name}` | `ProcessorProfile` (or dict) converting FLOPs to seconds and joules |
    | `duration` | `{spec.duration:g}` | episode length [s] |
    | `dt` | `{spec.dt:g}` | time step [s] |
    | `n_uav` | `{n}` | swarm size N |
    | any other `TaskSpec` field | this task's | `trajectory`, `anchors`, `landmarks`, `sensors`, `faults`, `filter`, `scoring` (validated) |

    ```python
    >>> import gymnasium as gym
    >>> import swarmloc.envs
    >>> env = gym.make("{task_id}", duration=2.0)
    >>> env.observation_space.shape, env.action_space.shape
    (({n}, {n_l}, {n_f}), ({n}, {n_l}))
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> sorted(info)[:3], info["accuracy"].shape
    (['accuracy', 'delay_ms', 'delay_penalty'], ({n},))

    ```

    ## Measurement Model

    {_measurement_model(spec)}

    ## Batch Shapes

    | API | observation | action | reward |
    |-----|-------------|--------|--------|
    | Gymnasium `gym.make` | `({n}, {n_l}, {n_f})` | `({n}, {n_l})` | scalar (team) |
    | Gymnasium `gym.make_vec` (B envs) | `(B, {n}, {n_l}, {n_f})` | `(B, {n}, {n_l})` | `(B,)` (team) |
    | PettingZoo `parallel_env` (per agent `uav_i`) | `({n_l}, {n_f})` | `({n_l},)` | scalar (own) |
    | torchrl `torchrl_env` (group `uav`) | `(B, {n}, {n_l}, {n_f})` | `(B, {n}, {n_l})` | `(B, {n}, 1)` (own) |

    The global state for centralized critics (PettingZoo `state()`, torchrl `"state"`) has
    {n * n_l * n_f + 7 * n} entries: the flattened observation, then each UAV's prior
    position (3) and velocity (3), then each UAV's prior position std (1).

    ## Version History

    {hist}
    """
