"""Virtual interaction: hypotheses propagated through the behaviour chain (interaction paper, §5).

A hypothesis H = (F, f) is a state vector and a chain state. At each frame the
real person's shape S^H is compared with the matching half of every hypothesis
(eq. 18); the virtual partner is the other half of the chosen hypothesis.

- :class:`SingleHypothesis` (§5.1): one hypothesis, replaced each frame by the
  potential continuation with the smallest error.
- :class:`MultipleHypotheses` (§5.2): N hypotheses in the manner of Isard and
  Blake's CONDENSATION: Gaussian likelihoods (eq. 20) weight the resampling of
  the prior into the posterior (eq. 19), whose stochastic extrapolations form
  the next prior; the response is the maximum-likelihood hypothesis (the
  paper's), the maximum a-posteriori one found by hypersphere counting
  (eq. 21), or CONDENSATION's own state estimate, the likelihood-weighted mean
  of the hypotheses (Isard and Blake).

Both are vectorised over hypotheses and work online, one observation per
:meth:`step`. Where the chain reaches its end state before the observed
interaction ends (long dance takes hold many interactions), a new interaction
begins: the single hypothesis is chosen again among all chain states, and
multiple hypotheses that ended are drawn again from the chain's occupancy.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from markovmotion.defaults import (  # the command line's defaults, defined there
    DEFAULT_RESPONSE,
    DEFAULT_RESYNC,
    DEFAULT_SIGMA,
    RESPONSES,
)
from markovmotion.models.chain.behaviour_chain import BehaviourChain, Hypotheses
from markovmotion.progress import track


def shape_errors(
    c: np.ndarray, observation: np.ndarray, roles: Sequence[slice]
) -> tuple[np.ndarray, np.ndarray]:
    """E(F, S^H) of eq. (18) for hypotheses' combined shapes ``c`` (N, d): distance from the
    observed shape to the person it matches best among ``roles`` (column slices of C);
    returns errors and roles (N,)."""
    errs = np.stack([np.linalg.norm(c[:, sl] - observation, axis=1) for sl in roles], axis=1)
    role = errs.argmin(axis=1)
    return errs[np.arange(len(c)), role], role


def likelihood_weights(errors: np.ndarray, sigma: float) -> np.ndarray:
    """Normalised Gaussian likelihoods exp(-E^2 / 2 sigma^2) of eq. (20), computed in log space."""
    log_w = -0.5 * (np.asarray(errors) / sigma) ** 2
    w = np.exp(log_w - log_w.max())
    return w / w.sum()


def hypersphere_mode(c: np.ndarray, radius: float | None = None) -> int:
    """Index of the hypothesis with the most hypotheses within ``radius`` of it (eq. 21).

    Without a radius, the median distance between the hypotheses is used (the
    paper sets d by experiment; the posterior's spread changes from frame to frame).
    """
    sq = (c**2).sum(axis=1)
    d2 = np.maximum(sq[:, None] - 2 * c @ c.T + sq[None], 0.0)
    if radius is None:
        r2 = np.median(d2[np.triu_indices(len(c), 1)]) if len(c) > 1 else 0.0
    else:
        r2 = radius**2
    return int((d2 <= r2).sum(axis=1).argmax())


def weighted_mean(c: np.ndarray, role: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, int]:
    """CONDENSATION's state estimate: the ``weights``-weighted mean of the shapes ``c`` (N, d).

    Hypotheses that put the real person in different halves of C do not
    average: the mean is over those of the role with the most weight; returns
    the mean shape and that role.
    """
    best = int(np.bincount(role, weights=weights).argmax())
    w = np.where(role == best, weights, 0.0)
    return w @ c / w.sum(), best


@dataclass
class Response:
    """The response of one frame: its combined shape vector, the real person's role (an index
    into the propagator's ``roles``) and the matching error."""

    shape: np.ndarray
    role: int
    error: float

    def __post_init__(self) -> None:
        # its own copy: a row of the frame's (hypotheses, d) array kept that whole array alive,
        # and a long take's responses held every frame's hypotheses (8 GB for 42,000 frames)
        self.shape = np.array(self.shape, dtype=float)


class Propagator:
    """Common part of both propagation schemes: chain, roles, online ``step`` and batch ``run``.

    Args:
        chain: a fitted :class:`BehaviourChain`.
        roles: the column slices of C that the real person's observed shape may
            match (person 0's and person 1's shape; one slice if the role is known).
        restart: begin a new interaction when the chain's end state is reached.
        seed: random seed (stochastic extrapolation and resampling).
    """

    def __init__(
        self,
        chain: BehaviourChain,
        roles: Sequence[slice],
        restart: bool = True,
        seed: int = 0,
    ):
        self.chain = chain
        self.roles = list(roles)
        self.restart = restart
        self.seed = seed
        self.reset()

    def reset(self) -> None:
        """Forget the interaction so far."""
        self.rng = np.random.default_rng(self.seed)
        self.hypotheses: Hypotheses | None = None

    def step(self, observation: np.ndarray) -> Response:
        raise NotImplementedError

    def run(self, observations: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Responses to a whole sequence (T, k): shape vectors (T, d), roles (T,) and errors (T,)."""
        self.reset()
        frames = np.asarray(observations, dtype=float)
        out = [self.step(o) for o in track(frames, "answering A's frames")]
        return (
            np.array([r.shape for r in out]),
            np.array([r.role for r in out]),
            np.array([r.error for r in out]),
        )

    def _seated(self, weights: np.ndarray, n: int | None) -> Hypotheses:
        """Hypotheses at chain states: all with positive ``weights`` (n None) or n drawn from them."""
        ch = self.chain
        if n is None:
            states = np.flatnonzero(weights[: ch.end_state] > 0)
        else:
            states = self.rng.choice(len(weights), n, p=weights)
        return ch.at(ch.state_vectors(states), states)


class SingleHypothesis(Propagator):
    """Single-hypothesis propagation (§5.1, steps 1-4).

    Args:
        resync: re-synchronisation margin (our addition; ``inf``: never, the
            paper's scheme). Each frame the hypothesis's continuations compete
            with every chain state entered afresh at its prototype (step 1
            again, over the chain's occupancy); a fresh entry replaces them if
            its error (eq. 18) is lower by more than ``resync``. Without it a
            wrong choice at a decision point can only be left at the end state.
            Default :data:`DEFAULT_RESYNC`, chosen by validation.
    """

    def __init__(
        self,
        chain: BehaviourChain,
        roles: Sequence[slice],
        resync: float = DEFAULT_RESYNC,
        restart: bool = True,
        seed: int = 0,
    ):
        self.resync = resync
        super().__init__(chain, roles, restart, seed)

    def step(self, observation: np.ndarray) -> Response:
        ch = self.chain
        if self.hypotheses is None:
            candidates = self._seated(ch.startprob_, None)
        else:
            candidates = ch.branch(self.hypotheses)
            if self.restart and np.all(candidates.state == ch.end_state):
                candidates = self._seated(ch.occupancy_, None)
        best, c, err, role = self._best(candidates, observation)
        if np.isfinite(self.resync) and self.hypotheses is not None:
            fresh = self._seated(ch.occupancy_, None)
            again = self._best(fresh, observation)
            if again[2] + self.resync < err:
                candidates, (best, c, err, role) = fresh, again
        self.hypotheses = candidates.take(np.array([best]))
        return Response(c, role, err)

    def _best(
        self, candidates: Hypotheses, observation: np.ndarray
    ) -> tuple[int, np.ndarray, float, int]:
        """The candidate with the smallest error (eq. 18): index, shape, error and role."""
        c = self.chain.current(candidates)
        err, role = shape_errors(c, observation, self.roles)
        best = int(err.argmin())
        return best, c[best], float(err[best]), int(role[best])


class MultipleHypotheses(Propagator):
    """Multiple-hypothesis propagation in the manner of CONDENSATION (§5.2, steps 1-6).

    Args:
        n_hypotheses: N (paper: 200).
        sigma: width of the Gaussian likelihood of eq. (20) (paper: 0.05; default:
            :data:`DEFAULT_SIGMA`, chosen by validation).
        response: ``"ml"`` (the paper's), ``"map"`` (hypersphere counting, eq. 21)
            or ``"mean"`` (the likelihood-weighted mean of the prior's hypotheses,
            i.e. the posterior mean of eq. 19).
        map_radius: d of eq. (21), a distance between combined shape vectors;
            None: the median distance between the posterior's hypotheses.
    """

    def __init__(
        self,
        chain: BehaviourChain,
        roles: Sequence[slice],
        n_hypotheses: int = 200,
        sigma: float = DEFAULT_SIGMA,
        response: str = DEFAULT_RESPONSE,
        map_radius: float | None = None,
        restart: bool = True,
        seed: int = 0,
    ):
        if response not in RESPONSES:
            raise ValueError(f"response must be one of {RESPONSES}, got {response!r}")
        self.n_hypotheses = n_hypotheses
        self.sigma = sigma
        self.response = response
        self.map_radius = map_radius
        super().__init__(chain, roles, restart, seed)

    def step(self, observation: np.ndarray) -> Response:
        ch = self.chain
        if self.hypotheses is None:
            prior = self._seated(ch.startprob_, self.n_hypotheses)
        else:
            prior = ch.advance(self.hypotheses, self.rng)
            ended = np.flatnonzero(prior.state == ch.end_state)
            if self.restart and len(ended):
                prior.put(ended, self._seated(ch.occupancy_, len(ended)))
        c = ch.current(prior)
        err, role = shape_errors(c, observation, self.roles)
        weights = likelihood_weights(err, self.sigma)
        pick = self.rng.choice(len(c), len(c), p=weights)
        self.hypotheses = prior.take(pick)
        if self.response == "mean":
            shape, r = weighted_mean(c, role, weights)
            return Response(shape, r, float(np.linalg.norm(shape[self.roles[r]] - observation)))
        if self.response == "ml":
            best = int(err.argmin())
        else:
            best = int(pick[hypersphere_mode(c[pick], self.map_radius)])
        return Response(c[best], int(role[best]), float(err[best]))
