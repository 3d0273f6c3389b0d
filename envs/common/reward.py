"""Rewards of the environments, from the metrics of one simulated tray test.

Three penalty terms, each in [0, 1]:

    cv_term       = min(CV, cv_worst) / cv_worst        CV at the target swath, %;
                                                        nothing landed -> 1 (worst)
    swath_term    = min(|W_eff - W_target| / W_target, 1)
                                                        W_eff: effective swath (largest
                                                        bout width with CV <= threshold)
    retained_term = 1 - landed mass / released mass     mass that never reached the trays

    penalty = cv_weight * cv_term + swath_weight * swath_term + retained_weight * retained_term

SpinnerDesign:   reward = -penalty                        in [-(sum of weights), 0]
SpreaderTuning:  reward = -penalty - step_cost + goal_bonus * [CV <= goal]
                                                          in [-(sum of weights) - step_cost,
                                                              goal_bonus - step_cost]
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from spreadgym.envs.common.config import RewardConfig, TuningRewardConfig
from spreadgym.spread.metrics import RunMetrics


@dataclass(frozen=True)
class Score:
    cv_percent: float  # measured CV at the target swath; cv_worst_percent when nothing landed
    effective_swath_m: float
    target_swath_m: float
    landed_fraction: float
    cv_term: float
    swath_term: float
    retained_term: float
    penalty: float

    def as_dict(self) -> dict:
        return {k: float(v) for k, v in asdict(self).items()}


def _finite_or(value, fallback: float) -> float:
    if value is None:
        return fallback
    value = float(value)
    return value if math.isfinite(value) else fallback


def score(metrics: RunMetrics, cfg: RewardConfig) -> Score:
    """Penalty terms of one run's metrics (`SimulationResult.metrics`)."""
    worst = float(cfg.cv_worst_percent)
    cv = min(max(_finite_or(metrics.cv_percent_at_target, worst), 0.0), worst)
    target = float(metrics.target_swath_m)
    effective = max(_finite_or(metrics.effective_swath_m, 0.0), 0.0)
    landed_fraction = min(max(_finite_or(metrics.landed_fraction, 0.0), 0.0), 1.0)
    cv_term = cv / worst
    swath_term = min(abs(effective - target) / target, 1.0) if target > 0 else 1.0
    retained_term = 1.0 - landed_fraction
    penalty = cfg.cv_weight * cv_term + cfg.swath_weight * swath_term + cfg.retained_weight * retained_term
    return Score(cv, effective, target, landed_fraction, cv_term, swath_term, retained_term, float(penalty))


def max_penalty(cfg: RewardConfig) -> float:
    return float(cfg.cv_weight + cfg.swath_weight + cfg.retained_weight)


def design_reward(s: Score) -> float:
    return float(-s.penalty)


def design_reward_bounds(cfg: RewardConfig) -> tuple[float, float]:
    return (-max_penalty(cfg), 0.0)


def tuning_reward(s: Score, cfg: TuningRewardConfig, reached_goal: bool) -> float:
    return float(-s.penalty - cfg.step_cost + (cfg.goal_bonus if reached_goal else 0.0))


def tuning_reward_bounds(cfg: TuningRewardConfig) -> tuple[float, float]:
    return (-max_penalty(cfg) - float(cfg.step_cost), float(cfg.goal_bonus) - float(cfg.step_cost))
