"""One Markdown page per registered task from its class docstring.

``swarmloc docs tasks`` writes them to ``docs/tasks/``. Pages are generated from ``__doc__``
over the Gymnasium registry (``swarmloc/`` namespace), so the docs are exactly what
``help(NLOSEnv)`` shows; an index page lists every task.
"""

from __future__ import annotations

import inspect

import gymnasium as gym

from swarmloc.envs.adapters.registration import register_tasks


_USAGE = """Every task is registered on `import swarmloc.envs` and served through four APIs:

```python
import gymnasium as gym
import swarmloc.envs

env = gym.make("swarmloc/NLOS-v0")                      # Gymnasium: obs (N, L, F), action (N, L), team reward
vec = gym.make_vec("swarmloc/NLOS-v0", num_envs=1024)   # batched vector env, next-step autoreset
par = swarmloc.envs.parallel_env("swarmloc/NLOS-v0")    # PettingZoo: agents uav_0..uav_{N-1}; swarmloc.envs.env(...) for AEC
trl = swarmloc.envs.torchrl_env("swarmloc/NLOS-v0", batch_size=1024)  # torchrl EnvBase, group "uav"
```

Keyword arguments override task-spec fields (`duration=5.0`, `sensors={"imu_sigma": 0.2}`), the
reward weights (`reward_weights={...}`), the method's declared `policy_flops` per UAV per step
(charged in the delay and energy terms) and the `processor` profile. `reset(seed=s)` plays
episode seed `s`, the same episode the bench suites call seed `s`."""


def task_pages() -> dict[str, str]:
    """File name → Markdown text for every registered swarmloc task, plus ``index.md``."""
    register_tasks()
    pages, index = {}, ["# swarmloc tasks", "", _USAGE, "", "| Task | Class | Summary |", "|------|-------|---------|"]
    for task_id in sorted(i for i in gym.registry if i.startswith("swarmloc/")):
        env_spec = gym.spec(task_id)
        module, name = env_spec.entry_point.split(":")
        cls = getattr(__import__(module, fromlist=[name]), name)
        doc = inspect.cleandoc(cls.__doc__ or "")
        title, _, body = doc.partition("\n")
        pages[f"{name.removesuffix('Env')}.md"] = (
            f"# {task_id}\n\n*{title.strip()}*\n\nClass `{module}.{name}`; "
            f"`max_episode_steps = {env_spec.max_episode_steps}`.\n{body}\n")
        index.append(f"| [`{task_id}`]({name.removesuffix('Env')}.md) | `{name}` | {title.partition(':')[2].strip()} |")
    pages["index.md"] = "\n".join(index) + "\n"
    return pages

