"""How the uncertainty analyses solve their problem, as values: the posterior
sampler ([`jaxcable.NUTS`][]) and the test design's optimiser with the lab's budget
([`jaxcable.TestDesign`][])."""

import equinox as eqx
from jaxtyping import PRNGKeyArray

from .._checks import require_int, require_number
from .budget import TestBudget
from .priors import PRIOR_SCALE


NOISE_MODELS = ("fitted", "robust")


class NUTS(eqx.Module):
    """The method of [`jaxcable.sample_posterior`][]: the Bayesian model of the
    data's noise and of the parameters' prior, and the No-U-Turn sampler that draws
    from the posterior they make.

    The noise model and the prior belong here rather than in the
    [`jaxcable.Problem`][]: the problem says what is measured and which parameters
    the data are to determine, as the least-squares fit reads it too; how the noise
    and the prior are modelled is part of the Bayesian method alone.

    **Fields:**

    - `num_samples`: draws kept per chain, >= 4 (default 500).
    - `num_chains`: chains, >= 1 (default 4; >= 2 for R-hat).
    - `num_warmup`: warm-up steps per chain, >= 1 (default 500; rounded up to a
        multiple of 25).
    - `max_doublings`: the largest NUTS tree depth, >= 1 (default 8: trajectories
        of at most 2^8 - 1 steps).
    - `key`: a `jax.random` key; `None` (default) `jax.random.key(0)`, so that a
        posterior is reproducible unless asked otherwise.
    - `noise`: the noise model, `"fitted"` (default: each test's noise standard
        deviation unknown and integrated out) or `"robust"` (fixed at the robust
        estimate from second differences); see [`jaxcable.sample_posterior`][].
    - `prior_scale`: the prior's standard deviation on the unconstrained scale the
        fit solves on, > 0 (default ln 10: a factor 10 on a positive
        parameter).

    **Raises:**

    `TypeError` (not an integer, not a number) or `ValueError` (out of range)
    naming the field.
    """

    num_samples: int = eqx.field(default=500, static=True)
    num_chains: int = eqx.field(default=4, static=True)
    num_warmup: int = eqx.field(default=500, static=True)
    max_doublings: int = eqx.field(default=8, static=True)
    key: PRNGKeyArray | None = None
    noise: str = eqx.field(default="fitted", static=True)
    prior_scale: float = eqx.field(default=PRIOR_SCALE, static=True)

    def __check_init__(self):
        require_int("num_samples", self.num_samples, 4)
        require_int("num_chains", self.num_chains, 1)
        require_int("num_warmup", self.num_warmup, 1)
        require_int("max_doublings", self.max_doublings, 1)
        if self.noise not in NOISE_MODELS:
            raise ValueError(
                f"`noise` must be one of {NOISE_MODELS}, got {self.noise!r}."
            )
        require_number("prior_scale", self.prior_scale, 0.0, strict=True)


class TestDesign(eqx.Module):
    """The method of [`jaxcable.design_test`][] and
    [`jaxcable.design_discriminating_test`][]: the lab's budget, within which the
    test is designed, and the Adam optimiser that designs it.

    **Fields:**

    - `budget`: the lab's constraints, a [`jaxcable.TestBudget`][] (duration,
        largest force, speed range, samples, blocks, noise).
    - `steps`: optimiser steps, >= 0 (default 40).
    - `learning_rate`: Adam's step on the unconstrained design variables, > 0
        (default 0.15).

    **Raises:**

    `TypeError` (not an integer, not a number) or `ValueError` (out of range)
    naming the field.
    """

    # Not collected by pytest although its name starts with "Test".
    __test__ = False

    budget: TestBudget = eqx.field(static=True)
    steps: int = eqx.field(default=40, static=True)
    learning_rate: float = eqx.field(default=0.15, static=True)

    def __check_init__(self):
        if not isinstance(self.budget, TestBudget):
            raise ValueError(
                "`budget` must be a jaxcable.TestBudget, got "
                f"{type(self.budget).__name__}."
            )
        require_int("steps", self.steps, 0)
        require_number("learning_rate", self.learning_rate, 0.0, strict=True)
