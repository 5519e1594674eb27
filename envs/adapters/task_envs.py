"""One Gymnasium class per registered task; each class docstring is the task's spec doc.

A class holds its task ID, a Description and a Version History; ``tasks.docs.task_doc``
adds every section that follows from the spec. Behaviour lives in ``SwarmLocEnv``. The
classes are built from two tables, ``DESCRIPTIONS`` (the hand-worded Descriptions; any
other task's is its spec factory's docstring) and ``_HISTORY``, so a task added to the
catalogue is registered, documented and tested at once.
"""

from __future__ import annotations

import inspect

from swarmloc.envs.adapters import registration
from swarmloc.envs.adapters.gym_env import SwarmLocEnv
from swarmloc.envs.tasks.docs import task_doc
from swarmloc.envs.tasks.catalogue import CATALOGUE
from swarmloc.envs.tasks.v1 import HISTORY_V1
from swarmloc.envs.tasks.v2 import HISTORY_V2

_V0 = ("v0: initial release (standard reward v0, processor profile stm32f427-cortex-m4f v0).",)
#: the TDOA tasks start at v1 (they came with the TDOA channel kind, beside the frozen v0 tasks)
_TDOA_V1 = ("v1: initial release, with the TDOA channel kind (standard reward v0, processor profile "
            "stm32f427-cortex-m4f v0).",)


def _history_before_v2(task_id: str) -> tuple[str, ...]:
    """The v0 and v1 lines of a v2 task whose ID existed before (none for a new task)."""
    v1 = task_id.replace("-v2", "-v1")
    if v1 in HISTORY_V1:
        return (_V0 if task_id.replace("-v2", "-v0") in CATALOGUE else ()) + (HISTORY_V1[v1],)
    return _TDOA_V1 if v1 == "swarmloc/TDOA-v1" else ()


#: Version History of the classes that are not plain v0 releases
_HISTORY: dict[str, tuple[str, ...]] = {
    "swarmloc/UTILFlight-v1": _V0 + ("v1: the anchors in the Vicon frame (the dataset's conversion of the survey, "
                                     "anchors_vicon.csv) instead of the raw total-station coordinates, 5–11 cm "
                                     "off; everything else as v0.",),
    **{task_id: _TDOA_V1 for task_id in CATALOGUE if "Tdoa" in task_id or task_id == "swarmloc/TDOA-v1"},
    # benchmark v1: a v1 task of a v0 family lists the v0 release first; a new task only its v1 line
    **{task_id: (_V0 if task_id.replace("-v1", "-v0") in CATALOGUE else ()) + (line,)
       for task_id, line in HISTORY_V1.items()},
    # benchmark v2: the earlier releases of the same ID's family and version, then the v2 line
    **{task_id: _history_before_v2(task_id) + (line,) for task_id, line in HISTORY_V2.items()},
}

_SCALE_TEXT = """
        scalability with a swarm of {n} UAVs (madrl Exp. 3).
        {n} UAVs circle inside a 20 × 20 m hall with eight wall anchors (range σ 0.2 m). Every
        second UAV flies through NLOS-heavy areas, so its anchor and peer links are biased at
        random; unverified peer links then spread its error to the rest of the swarm. Channel
        count grows with N (N − 1 peer slots per UAV)."""

_HYBRID_TEXT = """
        GPS with {p} % heavy-tailed hybrid noise on a leader–follower chain (imm-arkf).
        Nine drones fly a figure-eight of 20 m radius as a chain: the leader has a 0.1 m fix,
        followers 1 m GPS whose noise mixes Student-t and Gaussian parts ({p} % t), plus
        chain UWB ranging to their neighbours. Outliers from the t part should get low trust;
        followers 1–8 are scored."""

#: registered ID → the Description of its class, worded by hand (the first line is the summary);
#: a task without one is described by its spec factory's docstring
DESCRIPTIONS: dict[str, str] = {
    "swarmloc/Ideal-v0": """
        ideal conditions, Gaussian noise only (madrl Exp. 1).
        Four UAVs accelerate along straight lines for 15 s and then fly circles of 10 m radius,
        localised by six UWB anchors, peer ranging and the IMU. Nothing is faulty: the best
        trust is (nearly) uniform, and a method should lose little accuracy against it while
        saving energy by skipping redundant channels.""",
    "swarmloc/NLOS-v0": """
        random time-correlated NLOS bias on anchor and peer links (madrl Exp. 2).
        Same course as Ideal with eight anchors; every anchor and peer link turns non-line-of-
        sight at random, adding a positive Gauss–Markov range bias of up to 5 m for several
        seconds. The policy must spot biased links from their innovations and lower their
        trust.""",
    "swarmloc/NLOSStep-v0": """
        one anchor jumps +3 m between 20 s and 30 s (madrl Exp. 4/6 preset).
        A deterministic NLOS step on anchor 0, seen by every UAV, in an otherwise ideal
        eight-anchor scene; the fault window is scored separately. The classic test of
        reaction time and of trust recovery after the fault ends.""",
    **{f"swarmloc/Scale{n}-v0": _SCALE_TEXT.format(n=n) for n in (2, 4, 6, 8, 16, 32)},
    "swarmloc/CascadedFault-v0": """
        IMU fault cascade on two of four UAVs under sparse anchors (madrl Exp. 5).
        Three anchors only. From 20 s to 35 s UAVs 1 and 2 (paper nodes 2 and 3) get an
        accelerometer bias of [1.5, 1.2, 0.5] m/s² and receive no measurement: they dead-
        reckon blind and broadcast drifting estimates. Healthy UAVs 0 and 3 must stop trusting
        their peer links to the faulty ones or the error spreads; metrics use the healthy
        nodes.""",
    "swarmloc/CascadedFaultRandom-v0": """
        randomised IMU fault cascade (madrl Exp. 5, randomised).
        As CascadedFault, but which two UAVs fail, when (start 15–25 s), for how long
        (10–15 s) and how hard (bias 1.5–2 m/s²) are drawn per episode, so a policy cannot
        memorise the schedule.""",
    "swarmloc/VisionLoss-v0": """
        camera landmarks with 10 s vision outages, no anchors (pf-nn, dtvirm).
        Six UAVs circle in a 30 × 20 × 5 m hall with 20 landmarks seen by a camera within
        10 m, and range to each other over UWB. Between 30–40 s and 60–70 s the cameras see
        nothing, leaving peer ranging and the IMU; the first outage is scored separately.""",
    "swarmloc/Indoor-v0": """
        the pf-nn indoor scenario: landmarks and peer ranging, no anchors, no outages (pf-nn §3.1).
        VisionLoss-v0's hall, swarm and sensors without the camera outages: six UAVs circle
        in a 30 × 20 × 5 m hall with 20 landmarks (camera ≤ 10 m, σ 0.15 m) and peer UWB
        (σ 0.2 m) for 100 s. The nominal reference for the vision-loss task.""",
    **{f"swarmloc/HybridNoise{p}-v0": _HYBRID_TEXT.format(p=p) for p in (10, 30, 50)},
    "swarmloc/GradualFault-v0": """
        gradual GPS drift on followers of a leader–follower formation (federated filter paper).
        One leader with a 1 m fix and two followers with 10 m GPS, IMU and precise (0.03 m)
        UWB relative position to the leader, flying a slow turning line at 100 m altitude
        with dt = 1 s. From 100 s to 200 s the followers' GPS drifts at 0.1 m/s; a method
        should notice the slow ramp and lean on the leader link instead.""",
}


def task_class(task_id: str) -> type[SwarmLocEnv]:
    """The documented ``SwarmLocEnv`` subclass of a catalogue task, named ``registration.class_name(task_id)``.

    Its Description is ``DESCRIPTIONS[task_id]``, else the spec factory's docstring (its
    first letter lowered: it continues the ``"<Name>: "`` summary); its Version History is
    ``_HISTORY[task_id]``, else the v0 release line.
    """
    description = DESCRIPTIONS.get(task_id)
    if description is None:
        text = inspect.cleandoc(CATALOGUE[task_id].__doc__ or f"the {task_id} task.")
        description = text[0].lower() + text[1:]
    doc = task_doc(task_id, description, _HISTORY.get(task_id, _V0))
    return type(registration.class_name(task_id), (SwarmLocEnv,),
                {"__doc__": doc, "task_id": task_id, "__module__": __name__})


#: registered ID → task class (the registration and the docs generator use this); each class is
#: also a module attribute, the registration's string entry point
TASK_CLASSES: dict[str, type[SwarmLocEnv]] = {task_id: task_class(task_id) for task_id in CATALOGUE}
globals().update({cls.__name__: cls for cls in TASK_CLASSES.values()})
