"""One Gymnasium class per registered task; each class docstring is the task's spec doc.

A class holds its task ID, a Description and a Version History; ``task_docs.task_doc``
adds every section that follows from the spec. Behaviour lives in ``SwarmLocEnv``.
"""

from __future__ import annotations

import inspect

from swarmloc.envs.adapters import registration
from swarmloc.envs.adapters.gym_env import SwarmLocEnv
from swarmloc.envs.tasks.docs import task_doc
from swarmloc.envs.tasks.catalogue import CATALOGUE
from swarmloc.envs.tasks.v1 import HISTORY_V1

_V0 = ("v0: initial release (standard reward v0, processor profile stm32f427-cortex-m4f v0).",)
#: the TDOA tasks start at v1 (they came with the TDOA channel kind, beside the frozen v0 tasks)
_TDOA_V1 = ("v1: initial release, with the TDOA channel kind (standard reward v0, processor profile "
            "stm32f427-cortex-m4f v0).",)
#: Version History of the generated classes that are not plain v0 releases
_HISTORY: dict[str, tuple[str, ...]] = {
    "swarmloc/UTILFlight-v1": _V0 + ("v1: the anchors in the Vicon frame (the dataset's conversion of the survey, "
                                     "anchors_vicon.csv) instead of the raw total-station coordinates, 5–11 cm "
                                     "off; everything else as v0.",),
    **{task_id: _TDOA_V1 for task_id in CATALOGUE if "Tdoa" in task_id or task_id == "swarmloc/TDOA-v1"},
    # benchmark v1: a v1 task of a v0 family lists the v0 release first; a new task only its v1 line
    **{task_id: (_V0 if task_id.replace("-v1", "-v0") in CATALOGUE else ()) + (line,)
       for task_id, line in HISTORY_V1.items()},
}


class IdealEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Ideal-v0", """
        ideal conditions, Gaussian noise only (madrl Exp. 1).
        Four UAVs accelerate along straight lines for 15 s and then fly circles of 10 m radius,
        localised by six UWB anchors, peer ranging and the IMU. Nothing is faulty: the best
        trust is (nearly) uniform, and a method should lose little accuracy against it while
        saving energy by skipping redundant channels.""", _V0)
    task_id = "swarmloc/Ideal-v0"


class NLOSEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/NLOS-v0", """
        random time-correlated NLOS bias on anchor and peer links (madrl Exp. 2).
        Same course as Ideal with eight anchors; every anchor and peer link turns non-line-of-
        sight at random, adding a positive Gauss–Markov range bias of up to 5 m for several
        seconds. The policy must spot biased links from their innovations and lower their
        trust.""", _V0)
    task_id = "swarmloc/NLOS-v0"


class NLOSStepEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/NLOSStep-v0", """
        one anchor jumps +3 m between 20 s and 30 s (madrl Exp. 4/6 preset).
        A deterministic NLOS step on anchor 0, seen by every UAV, in an otherwise ideal
        eight-anchor scene; the fault window is scored separately. The classic test of
        reaction time and of trust recovery after the fault ends.""", _V0)
    task_id = "swarmloc/NLOSStep-v0"


_SCALE_TEXT = """
        scalability with a swarm of {n} UAVs (madrl Exp. 3).
        {n} UAVs circle inside a 20 × 20 m hall with eight wall anchors (range σ 0.2 m). Every
        second UAV flies through NLOS-heavy areas, so its anchor and peer links are biased at
        random; unverified peer links then spread its error to the rest of the swarm. Channel
        count grows with N (N − 1 peer slots per UAV)."""


class Scale2Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Scale2-v0", _SCALE_TEXT.format(n=2), _V0)
    task_id = "swarmloc/Scale2-v0"


class Scale4Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Scale4-v0", _SCALE_TEXT.format(n=4), _V0)
    task_id = "swarmloc/Scale4-v0"


class Scale6Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Scale6-v0", _SCALE_TEXT.format(n=6), _V0)
    task_id = "swarmloc/Scale6-v0"


class Scale8Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Scale8-v0", _SCALE_TEXT.format(n=8), _V0)
    task_id = "swarmloc/Scale8-v0"


class Scale16Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Scale16-v0", _SCALE_TEXT.format(n=16), _V0)
    task_id = "swarmloc/Scale16-v0"


class Scale32Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Scale32-v0", _SCALE_TEXT.format(n=32), _V0)
    task_id = "swarmloc/Scale32-v0"


class CascadedFaultEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/CascadedFault-v0", """
        IMU fault cascade on two of four UAVs under sparse anchors (madrl Exp. 5).
        Three anchors only. From 20 s to 35 s UAVs 1 and 2 (paper nodes 2 and 3) get an
        accelerometer bias of [1.5, 1.2, 0.5] m/s² and receive no measurement: they dead-
        reckon blind and broadcast drifting estimates. Healthy UAVs 0 and 3 must stop trusting
        their peer links to the faulty ones or the error spreads; metrics use the healthy
        nodes.""", _V0)
    task_id = "swarmloc/CascadedFault-v0"


class CascadedFaultRandomEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/CascadedFaultRandom-v0", """
        randomised IMU fault cascade (madrl Exp. 5, randomised).
        As CascadedFault, but which two UAVs fail, when (start 15–25 s), for how long
        (10–15 s) and how hard (bias 1.5–2 m/s²) are drawn per episode, so a policy cannot
        memorise the schedule.""", _V0)
    task_id = "swarmloc/CascadedFaultRandom-v0"


class VisionLossEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/VisionLoss-v0", """
        camera landmarks with 10 s vision outages, no anchors (pf-nn, dtvirm).
        Six UAVs circle in a 30 × 20 × 5 m hall with 20 landmarks seen by a camera within
        10 m, and range to each other over UWB. Between 30–40 s and 60–70 s the cameras see
        nothing, leaving peer ranging and the IMU; the first outage is scored separately.""", _V0)
    task_id = "swarmloc/VisionLoss-v0"


class IndoorEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/Indoor-v0", """
        the pf-nn indoor scenario: landmarks and peer ranging, no anchors, no outages (pf-nn §3.1).
        VisionLoss-v0's hall, swarm and sensors without the camera outages: six UAVs circle
        in a 30 × 20 × 5 m hall with 20 landmarks (camera ≤ 10 m, σ 0.15 m) and peer UWB
        (σ 0.2 m) for 100 s. The nominal reference for the vision-loss task.""", _V0)
    task_id = "swarmloc/Indoor-v0"


_HYBRID_TEXT = """
        GPS with {p} % heavy-tailed hybrid noise on a leader–follower chain (imm-arkf).
        Nine drones fly a figure-eight of 20 m radius as a chain: the leader has a 0.1 m fix,
        followers 1 m GPS whose noise mixes Student-t and Gaussian parts ({p} % t), plus
        chain UWB ranging to their neighbours. Outliers from the t part should get low trust;
        followers 1–8 are scored."""


class HybridNoise10Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/HybridNoise10-v0", _HYBRID_TEXT.format(p=10), _V0)
    task_id = "swarmloc/HybridNoise10-v0"


class HybridNoise30Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/HybridNoise30-v0", _HYBRID_TEXT.format(p=30), _V0)
    task_id = "swarmloc/HybridNoise30-v0"


class HybridNoise50Env(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/HybridNoise50-v0", _HYBRID_TEXT.format(p=50), _V0)
    task_id = "swarmloc/HybridNoise50-v0"


class GradualFaultEnv(SwarmLocEnv):
    __doc__ = task_doc("swarmloc/GradualFault-v0", """
        gradual GPS drift on followers of a leader–follower formation (federated filter paper).
        One leader with a 1 m fix and two followers with 10 m GPS, IMU and precise (0.03 m)
        UWB relative position to the leader, flying a slow turning line at 100 m altitude
        with dt = 1 s. From 100 s to 200 s the followers' GPS drifts at 0.1 m/s; a method
        should notice the slow ramp and lean on the leader link instead.""", _V0)
    task_id = "swarmloc/GradualFault-v0"


#: registered ID → task class (the registration and the docs generator use this)
TASK_CLASSES: dict[str, type[SwarmLocEnv]] = {
    cls.task_id: cls for cls in (
        IdealEnv, NLOSEnv, NLOSStepEnv, Scale2Env, Scale4Env, Scale6Env, Scale8Env, Scale16Env, Scale32Env,
        CascadedFaultEnv, CascadedFaultRandomEnv, VisionLossEnv, IndoorEnv, HybridNoise10Env, HybridNoise30Env,
        HybridNoise50Env, GradualFaultEnv,
    )
}


def generated_task_class(task_id: str) -> type[SwarmLocEnv]:
    """A task class for a catalogue task without a hand-written one above.

    Its Description is the spec factory's docstring, so a task added to the catalogue is
    registered, documented and tested at once; write a class above to word it better.
    """
    factory = CATALOGUE[task_id]
    text = inspect.cleandoc(factory.__doc__ or f"the {task_id} task.")
    name = registration.class_name(task_id)
    doc = task_doc(task_id, text[0].lower() + text[1:], _HISTORY.get(task_id, _V0))
    return type(name, (SwarmLocEnv,), {"__doc__": doc, "task_id": task_id, "__module__": __name__})


for _task_id in CATALOGUE:
    if _task_id not in TASK_CLASSES:
        TASK_CLASSES[_task_id] = globals()[registration.class_name(_task_id)] = generated_task_class(_task_id)

