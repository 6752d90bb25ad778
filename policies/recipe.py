"""The default training recipe: what ``tissue-retract train`` does when ``--algo`` is not given.

The paper's algorithms train for a fixed 1,000 episodes, one core collecting and learning in turn. The
recipe aims at a competent policy in as little wall time as a 2-core machine allows:

- Behaviour cloning from 200 of the scripted expert's demonstrations first (CoL's pretraining),
  evaluated at once: on Tasks I-III that alone usually reaches the target (``bench train``). Then
  CoL's combined actor loss with a strong cloning term: with the critic still untrained, the paper's
  weight (5) let the actor's Q term undo the cloned policy within tens of episodes (Target, from 30
  demonstrations: 65 % held-out after cloning, 0 % 44 episodes later).
- No uniformly random steps: the cloned policy plus exploration noise explores where it matters.
- Collection in a worker process, the updates running while the task simulates, and half of the
  demonstrations collected there while this process collects the other half (:mod:`policies.collect`).
- Early stopping on held-out success: an evaluation after cloning, then one every 50 episodes (an
  evaluation of 100 episodes simulates twice what 50 training episodes do); the run ends at the first
  that reaches :attr:`Recipe.stop_at_success`, and that evaluation's policy is ``policy.safetensors``. The bar is
  97 % of 100 held-out episodes: at 96 % of 50 a Lift policy passed 48 of its 50 and scored 93 % on
  100 unseen ones (``bench train``, seed 2). A policy that succeeds 93 % of the time passes 48 of 50
  with probability 0.31, 97 of 100 with 0.07 (binomial).

Each field can still be overridden on the command line (``--demos``, ``--episodes``, ``--eval-every``,
``--eval-episodes``, ``--set FIELD=VALUE``).

``train --robust`` (:data:`ROBUST_RECIPE`) is this recipe's cloning over the robustness sweep's ranges
(:data:`SWEEP_VARY`: stiffness, size, observation noise, action latency, grip friction): the
demonstrations and the evaluation that scores the policy draw from them, so it is judged on what the sweep
judges, not on the nominal task. Cloning is what carries it: on MultiSite (held-out success on 100
randomized episodes) 200 demonstrations and 3,000 updates cloned 65 %, 600 and 10,000 91 %, 1,000 and
20,000 90 %. CoL's training after it lowered the success at every evaluation (90 % after cloning, 53-71 %
over the next 550 episodes), so the recipe stops after cloning (``--episodes N`` trains on). It takes
600 demonstrations and 10,000 updates, within 80 % of a 570 s budget (the whole command within 10
minutes); ``docs/learning.md`` has the commands.
"""

from __future__ import annotations

from dataclasses import dataclass

from policies.budget import PREPARATION_SHARE
from policies.config import TrainConfig

__all__ = ["DEFAULT_RECIPE", "ROBUST_RECIPE", "SWEEP_VARY", "Recipe"]

#: The robustness sweep's ranges (``docs/robustness.md``): what ``train --robust`` trains and judges on.
SWEEP_VARY = "stiffness=0.3:3x,size=0.8:1.2x,obs_noise=0:0.002,latency=0:3,friction=0.7:1.3x"


@dataclass(frozen=True)
class Recipe:
    """A training recipe: the algorithm's configuration and how the run is driven.

    Attributes:
        name: Shown in reports and recorded in checkpoints' commands.
        config: The algorithm and its hyperparameters.
        demos: Demonstration episodes.
        episodes: Most training episodes (early stopping usually ends the run long before); 0: cloning only.
        eval_every: Evaluate every this many episodes.
        eval_episodes: Held-out episodes per evaluation.
        stop_at_success: Stop at the first evaluation with at least this success rate.
        overlap: Collect in a worker process while learning.
        vary: Train over these ranges (``train --vary``'s string) unless ``--vary`` says otherwise: every
            episode, demonstration and evaluation draws its conditions from them. None: the nominal task.
        budget_s: The whole command's wall-clock budget [s] unless ``--budget-s`` says otherwise; None: none.
        preparation_share: Under a budget, the share of it demonstrations and pretraining may take.
        lag_blind_demos: Demonstrations from the expert moving without knowing the actions still in flight
            (:class:`sim.expert.ScriptedExpert`'s ``lag_blind``).
    """

    name: str
    config: TrainConfig
    demos: int
    episodes: int
    eval_every: int
    eval_episodes: int
    stop_at_success: float
    overlap: bool = True
    vary: str | None = None
    budget_s: float | None = None
    preparation_share: float = PREPARATION_SHARE
    lag_blind_demos: bool = False


#: ``tissue-retract train`` without ``--algo``.
DEFAULT_RECIPE = Recipe(
    name="fast",
    config=TrainConfig(algo="col", bc_pretrain_steps=3_000, bc_weight=50.0, random_steps=0, updates_per_episode=50),
    demos=200,
    episodes=2_000,
    eval_every=50,
    eval_episodes=100,
    stop_at_success=0.97,
)


#: ``tissue-retract train --robust``: cloning over the robustness sweep's ranges, within 10 minutes.
ROBUST_RECIPE = Recipe(
    name="robust",
    config=TrainConfig(algo="col", bc_pretrain_steps=10_000, bc_weight=50.0, random_steps=0, updates_per_episode=50),
    demos=600,
    episodes=0,
    eval_every=50,
    eval_episodes=100,
    stop_at_success=0.97,
    vary=SWEEP_VARY,
    budget_s=570.0,
    preparation_share=0.8,
    lag_blind_demos=True,
)
