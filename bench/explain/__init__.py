"""Explaining trust decisions: per-feature attributions for any Track A method (madrl Experiment 4).

| module | what |
|---|---|
| ``attributions`` | the API: :func:`explain`, :func:`attribute`, :class:`Attributions` ``(T, B, N, L, F)`` |
| ``episode`` | :func:`replay`: fly a method through ``TrustEnvBatch`` and record what it saw and did |
| ``features`` | the features, their seven groups and the baselines (``nominal``, ``zeros``) |
| ``gradients`` | Captum integrated gradients of a torch policy's differentiable form |
| ``shapley`` | Captum Shapley value sampling of any method's ``act`` |
| ``report`` | the Table 5-style summary (Markdown + JSON) |
| ``figure`` | the Figure 6 chain: perception → decision → result, and the attributions |

``swarmloc explain`` (``cli/explain.py``) runs them for one episode.
"""

from swarmloc.bench.explain.attributions import EXPLAINERS, Attributions, Explanation, attribute, explain
from swarmloc.bench.explain.episode import Episode, replay

__all__ = ["EXPLAINERS", "Attributions", "Episode", "Explanation", "attribute", "explain", "replay"]
