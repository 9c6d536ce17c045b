"""Structured two-level behaviour model: a VLMM over key prototypes and atomic behaviours (§4).

Key prototypes (eq. 10) are the prototypes at which the speed |dC| along the
training prototype sequences is a local minimum below a threshold; they cut
every sequence into atomic behaviours a_ij (from key k_i to key k_j). The
frames of each atomic behaviour's examples are clustered by dynamic time
warping, and each cluster becomes one template (eq. 11) by re-sampling to a
common length, averaging and re-quantising to prototypes; a template's
probability is its cluster's share of the examples. A VLMM over the key
sequence gives P(k_j | s k_i), hence P(template | s k_i) (eq. 12).

Generation traverses the key automaton and replaces each key pair by a
template; prediction matches the prototypes seen since the last key against
the prefixes of every template leaving that key (open-end DTW), weighs the
matches by the model (eqs. 13-14), continues the best template and then the
key automaton.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial.distance import squareform
from sklearn.base import clone

from markovmotion.algorithms.dtw import dtw_distance_matrix, open_end_dtw
from markovmotion.algorithms.vector_quantisation import collapse_repeats, nearest_prototype
from markovmotion.core.motion import Motion
from markovmotion.errors import ModelFormatError
from markovmotion.limits import MAX_FRAMES, check_length
from markovmotion.models.base import Model
from markovmotion.models.vlmm.behaviour import BehaviourModel, call_rng
from markovmotion.models.vlmm.prediction_suffix_tree import VLMM
from markovmotion.state import (
    StateError,
    check_distribution_rows,
    check_index,
    check_lengths,
    check_shape,
    is_fitted,
    require,
    require_types,
)


def key_prototypes(
    sequences: Sequence[np.ndarray], speeds: np.ndarray, threshold: float, n_keys: int
) -> np.ndarray:
    """The ``n_keys`` prototypes most often at a local minimum of speed below ``threshold`` (eq. 10).

    Args:
        sequences: collapsed prototype sequences.
        speeds: (K,) |dC| of each prototype.
    """
    counts = np.zeros(len(speeds), dtype=int)
    for s in sequences:
        v = speeds[s]
        interior = (v[1:-1] <= v[:-2]) & (v[1:-1] <= v[2:])
        minimum = np.r_[False, interior, False] & (v < threshold)
        np.add.at(counts, s[minimum], 1)
    ranked = np.argsort(-counts, kind="stable")
    return np.sort(ranked[: min(n_keys, int((counts > 0).sum()))])


def key_positions(tokens: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Indices in ``tokens`` where a key prototype other than the previous key occurs."""
    at = np.flatnonzero(np.isin(tokens, keys))
    if len(at) == 0:
        return at
    return at[np.r_[True, tokens[at][1:] != tokens[at][:-1]]]


def resample(sequence: np.ndarray, n: int) -> np.ndarray:
    """(n, D) linear re-sampling of a (m, D) sequence over the same span."""
    sequence = np.asarray(sequence, dtype=float)
    if len(sequence) == 1:
        return np.repeat(sequence, n, axis=0)
    old = np.linspace(0.0, 1.0, len(sequence))
    new = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(new, old, col) for col in sequence.T], axis=1)


def cluster_sequences(sequences: Sequence[np.ndarray], max_distance: float) -> np.ndarray:
    """Cluster labels (0-based) by average-linkage on length-normalised DTW distances."""
    if len(sequences) == 1:
        return np.zeros(1, dtype=int)
    d = dtw_distance_matrix(list(sequences))
    lengths = np.array([len(s) for s in sequences])
    d /= lengths[:, None] + lengths[None, :]
    tree = linkage(squareform(d, checks=False), method="average")
    return fcluster(tree, max_distance, criterion="distance") - 1


def load_behaviour(path: str | os.PathLike[str]) -> BehaviourModel | StructuredBehaviourModel:
    """The behaviour model in ``path``, plain or structured (what ``vlmm train`` writes).

    Raises:
        ModelFormatError: not a model file, or a model of another family.
    """
    model = Model.load(path)
    if not isinstance(model, BehaviourModel | StructuredBehaviourModel):
        raise ModelFormatError(
            path, f"is a {model.KIND!r} model, expected 'vlmm' or 'structured_vlmm'"
        )
    return model


class StructuredBehaviourModel(Model):
    """Key prototypes, atomic-behaviour templates and a VLMM over keys (§4).

    Args:
        prototype_model: the prototype-level model (prototypes, pipeline, and
            the prototype VLMM it is compared with); fitted on the same motions.
        max_memory: N of the key-level VLMM.
        epsilon: its KL threshold.
        key_speed_quantile: threshold of eq. 10 as a quantile of the
            prototypes' speeds.
        n_keys: number of key prototypes kept (the most frequent minima).
        cluster_distance: average DTW distance per aligned frame (in augmented
            configuration units) below which examples share a template.
        unseen_threshold: below this best posterior score (eq. 13) the key
            history is dropped and eq. 14 alone decides (§4.4).

    Learnt attributes: ``prototype_model_``, ``keys_`` (prototype ids),
    ``vlmm_`` (over key indices), ``train_keys_`` / ``train_key_lengths_``,
    templates as ``template_tokens_`` (concatenated prototype ids),
    ``template_tokens_lengths_``, ``template_pairs_`` (n, 2) key indices (i, j)
    and ``template_probs_`` P(template | a_ij), ``train_files_``; :func:`fit_index
    <markovmotion.models.vlmm.behaviour.fit_index>` adds ``category_``, ``labels_`` and
    ``held_out_files_``. Randomness at call time defaults to the prototype model's
    ``random_state``.
    """

    KIND = "structured_vlmm"
    VERBS = ("generate", "predict", "score")

    @property
    def takes_arrays(self) -> bool:
        """Contour models learn and predict from contour arrays (:meth:`Model.takes_arrays`):
        the fitted prototype model's kind, before ``fit`` the one given."""
        base = getattr(self, "prototype_model_", None) or self.prototype_model
        return bool(getattr(base, "is_contour", False))

    def __init__(
        self,
        prototype_model: BehaviourModel | None = None,
        max_memory: int = 4,
        epsilon: float = 1e-4,
        key_speed_quantile: float = 0.2,
        n_keys: int = 12,
        cluster_distance: float = 1.0,
        unseen_threshold: float = 0.01,
    ):
        self.prototype_model = prototype_model
        self.max_memory = max_memory
        self.epsilon = epsilon
        self.key_speed_quantile = key_speed_quantile
        self.n_keys = n_keys
        self.cluster_distance = cluster_distance
        self.unseen_threshold = unseen_threshold

    # ---------------------------------------------------------------- fitting
    def fit(self, motions: Sequence[Motion] | Sequence[np.ndarray]) -> StructuredBehaviourModel:
        """Fit the prototype model, then keys, templates and the key VLMM; returns self.

        With a ``configuration="contour"`` prototype model, ``motions`` are contour
        configurations (F, 2n) (§2.1.1) and generation returns such arrays."""
        base = clone(self.prototype_model or BehaviourModel()).fit(motions)
        self.train_files_ = list(base.train_files_)  # what record_training would give
        self.prototype_model_ = base
        feats = base.observe(motions)
        runs = [collapse_repeats(nearest_prototype(f, base.prototypes_)) for f in feats]
        speeds = self._speeds()
        self.keys_ = key_prototypes(
            [r[0] for r in runs],
            speeds,
            np.quantile(speeds, self.key_speed_quantile),
            self.n_keys,
        )
        if len(self.keys_) < 2:
            raise ValueError("fewer than two key prototypes: raise key_speed_quantile")
        key_index = np.full(len(speeds), -1)
        key_index[self.keys_] = np.arange(len(self.keys_))
        examples: dict[tuple[int, int], list[np.ndarray]] = {}
        key_seqs = []
        for f, (tokens, starts) in zip(feats, runs, strict=True):
            at = key_positions(tokens, self.keys_)
            key_seqs.append(key_index[tokens[at]])
            for a, b in zip(at[:-1], at[1:], strict=True):
                pair = (int(key_index[tokens[a]]), int(key_index[tokens[b]]))
                examples.setdefault(pair, []).append(f[starts[a] : starts[b] + 1])
        self.train_keys_ = np.concatenate(key_seqs)
        self.train_key_lengths_ = np.array([len(k) for k in key_seqs])
        self._fit_templates(examples)
        self.vlmm_ = VLMM(self.max_memory, self.epsilon).fit(
            self.key_sequences(), n_symbols=len(self.keys_)
        )
        return self

    def _speeds(self) -> np.ndarray:
        _, dc = self.prototype_model_.knots(np.arange(len(self.prototype_model_.prototypes_)))
        return np.linalg.norm(dc, axis=1)

    def _fit_templates(self, examples: dict[tuple[int, int], list[np.ndarray]]) -> None:
        """One template per DTW cluster of each atomic behaviour's examples (§4.1)."""
        base = self.prototype_model_
        tokens, lengths, pairs, probs = [], [], [], []
        for (i, j), seqs in sorted(examples.items()):
            labels = cluster_sequences(seqs, self.cluster_distance)
            for label in np.unique(labels):
                members = [s for s, lab in zip(seqs, labels, strict=True) if lab == label]
                n = int(np.median([len(s) for s in members]))
                mean = np.mean([resample(s, n) for s in members], axis=0)
                tpl, _ = collapse_repeats(nearest_prototype(mean, base.prototypes_))
                tpl = np.r_[self.keys_[i], tpl[(tpl != self.keys_[i]) & (tpl != self.keys_[j])]]
                tpl = np.r_[collapse_repeats(tpl)[0], self.keys_[j]]
                tokens.append(tpl)
                lengths.append(len(tpl))
                pairs.append((i, j))
                probs.append(len(members) / len(seqs))
        self.template_tokens_ = np.concatenate(tokens)
        self.template_tokens_lengths_ = np.array(lengths)
        self.template_pairs_ = np.array(pairs)
        self.template_probs_ = np.array(probs)

    def check_state(self) -> None:
        """The learnt parts a model file must hold, and that they fit: keys_ prototype ids
        of prototype_model_, one symbol of vlmm_ each; training keys key indices; templates
        prototype ids, one (i, j) key pair each, P(template | a_ij) summing to 1 per pair."""
        if not is_fitted(self):
            return
        require(self, "train_files_", "train_keys_", "train_key_lengths_", "template_tokens_")
        require(self, "template_tokens_lengths_", "template_pairs_", "template_probs_")
        require_types(self, prototype_model_=BehaviourModel, vlmm_=VLMM)
        k = len(self.prototype_model_.prototypes_)
        n_keys = len(check_index("keys_", check_shape("keys_", self.keys_, (None,)), k))
        if self.vlmm_.n_symbols_ != n_keys:
            raise StateError(f"keys_: {n_keys} keys, vlmm_ has {self.vlmm_.n_symbols_} symbols")
        keys = check_shape("train_keys_", self.train_keys_, (None,))
        check_lengths(
            "train_key_lengths_",
            self.train_key_lengths_,
            len(check_index("train_keys_", keys, n_keys)),
        )
        tokens = check_shape("template_tokens_", self.template_tokens_, (None,))
        check_lengths(
            "template_tokens_lengths_",
            self.template_tokens_lengths_,
            len(check_index("template_tokens_", tokens, k)),
        )
        n = len(self.template_tokens_lengths_)
        pairs = check_index(
            "template_pairs_", check_shape("template_pairs_", self.template_pairs_, (n, 2)), n_keys
        )
        probs = check_shape("template_probs_", self.template_probs_, (n,))
        order = np.lexsort((pairs[:, 1], pairs[:, 0]))
        _, starts = np.unique(pairs[order], axis=0, return_index=True)
        check_distribution_rows("template_probs_", probs[order], np.r_[starts, n])

    def key_sequences(self) -> list[np.ndarray]:
        """The key-index sequences of the training motions."""
        return np.split(self.train_keys_, np.cumsum(self.train_key_lengths_)[:-1])

    def with_key_memory(
        self, max_memory: int, epsilon: float | None = None
    ) -> StructuredBehaviourModel:
        """The same keys and templates with a key VLMM of another maximum memory."""
        other = copy.copy(self)
        other.max_memory = max_memory
        eps = self.epsilon if epsilon is None else epsilon
        other.vlmm_ = VLMM(max_memory, eps).fit(self.key_sequences(), n_symbols=len(self.keys_))
        return other

    # -------------------------------------------------------------- templates
    @property
    def n_atomic_behaviours(self) -> int:
        return len({tuple(p) for p in self.template_pairs_})

    def template(self, index: int) -> np.ndarray:
        """The prototype sequence of template ``index`` (from key i to key j)."""
        end = np.cumsum(self.template_tokens_lengths_)
        return self.template_tokens_[end[index] - self.template_tokens_lengths_[index] : end[index]]

    def _templates_from(self, i: int) -> np.ndarray:
        return np.flatnonzero(self.template_pairs_[:, 0] == i)

    @property
    def random_state(self) -> int | None:
        """The prototype model's ``random_state`` (seeds stochastic verbs given no ``rng``)."""
        return self.prototype_model_.random_state

    def _choose_template(self, i: int, j: int, rng: np.random.Generator | None) -> int:
        """A template of a_ij: sampled from P(template | a_ij), else the most probable."""
        ids = np.flatnonzero((self.template_pairs_[:, 0] == i) & (self.template_pairs_[:, 1] == j))
        p = self.template_probs_[ids]
        return int(ids[np.argmax(p)] if rng is None else rng.choice(ids, p=p / p.sum()))

    def _expand(
        self,
        last_key: int,
        state: int,
        tokens: list[int],
        time: float,
        horizon: float,
        rng: np.random.Generator | None,
    ) -> list[int]:
        """Extend ``tokens`` (ending at key ``last_key``, reached at ``time`` frames) by key
        steps from ``state``, each expanded into a template, until ``horizon`` is covered."""
        pair_tau = self.prototype_model_.pair_intervals
        s = np.array([state])
        while time < horizon:
            key, s = self.vlmm_.step(s, rng)
            tpl = self.template(self._choose_template(last_key, int(key[0]), rng))
            seq = np.r_[tokens[-1], tpl[1:]]  # the template starts at the last key
            time += float(pair_tau[seq[:-1], seq[1:]].sum())
            tokens.extend(int(v) for v in tpl[1:])
            last_key = int(key[0])
        return tokens

    # ------------------------------------------------------------- generation
    def generate_tokens(
        self, seconds: float, rng: np.random.Generator | None = None, stochastic: bool = True
    ) -> np.ndarray:
        """Prototypes of a new routine: key traversal, each key pair replaced by a template (§4.3).

        Drawn when ``stochastic`` (from ``rng``, else seeded with ``random_state``),
        else the most likely keys and templates.
        """
        seconds = check_length(seconds, self.fps, MAX_FRAMES, "seconds")  # as the VLMM's
        rng = call_rng(rng, stochastic, self.random_state)
        start = self.vlmm_.start_state(rng)
        memory = self.vlmm_.memories_[start]
        first = (
            int(memory[-1])
            if len(memory) and memory[-1] >= 0
            else int(np.argmax(self.vlmm_.symbol_probs_))
        )
        return np.array(
            self._expand(first, start, [int(self.keys_[first])], 0.0, seconds * self.fps, rng)
        )

    def generate(
        self, seconds: float, rng: np.random.Generator | None = None, stochastic: bool = True
    ) -> Motion:
        """A new routine of ``seconds`` (plus its first frame) on the training skeleton.

        Drawn when ``stochastic`` (from ``rng``, else seeded with ``random_state``),
        else the most likely keys and templates.
        """
        base = self.prototype_model_
        configs = base.synthesize(self.generate_tokens(seconds, rng, stochastic))
        return base.to_motion(configs[: int(round(seconds * self.fps)) + 1])

    # ------------------------------------------------------------- prediction
    def prepare(
        self, features: np.ndarray, frames: Sequence[int] | None = None
    ) -> list[tuple[np.ndarray, int, int]] | dict[int, tuple[np.ndarray, int, int]]:
        """Per frame: the template continuation found by Bayesian template matching (§4.4).

        Returns, for every frame (a list), or for ``frames`` alone (a dict by frame: what
        :meth:`predict` needs of a long observation, its last frame; matching every frame
        of a 100,000-frame take took 150 s), ``(remaining prototypes, next key state, next
        key)``: the rest of the best template after the matched position tau, the key
        automaton's state once that template's end key is reached, and that key.
        """
        base = self.prototype_model_
        tokens, starts = collapse_repeats(nearest_prototype(features, base.prototypes_))
        at = key_positions(tokens, self.keys_)
        key_index = np.full(len(base.prototypes_), -1)
        key_index[self.keys_] = np.arange(len(self.keys_))
        key_states = self.vlmm_.recognise(key_index[tokens[at]])
        protos = base.prototypes_
        out = {}
        cache: dict[tuple[int, int], tuple[np.ndarray, int, int]] = {}
        for t in range(len(features)) if frames is None else (int(f) for f in frames):
            r = int(np.searchsorted(starts, t, side="right") - 1)
            k = int(np.searchsorted(at, r, side="right") - 1)
            lo = at[k] if k >= 0 else 0
            if (lo, r) not in cache:
                state = int(key_states[k]) if k >= 0 else 0
                last = int(key_index[tokens[at[k]]]) if k >= 0 else -1
                cache[(lo, r)] = self._match(protos[tokens[lo : r + 1]], last, state)
            out[t] = cache[(lo, r)]
        return list(out.values()) if frames is None else out

    def _match(self, observed: np.ndarray, last: int, state: int) -> tuple[np.ndarray, int, int]:
        """Best template for prototypes ``observed`` since key ``last`` (eqs. 12-14)."""
        protos = self.prototype_model_.prototypes_
        ids = self._templates_from(last) if last >= 0 else np.arange(len(self.template_probs_))
        costs, taus = np.empty(len(ids)), np.empty(len(ids), dtype=int)
        for n, i in enumerate(ids):
            costs[n], taus[n] = open_end_dtw(observed, protos[self.template(i)])
        like = 1.0 - costs / costs.sum() if len(ids) > 1 and costs.sum() > 0 else np.ones(len(ids))
        ends = self.template_pairs_[ids, 1]
        prior = self.template_probs_[ids] * self.vlmm_.output_probs(state)[ends]
        score = like * prior
        if last < 0 or score.max() < self.unseen_threshold:  # unseen: lose the key history
            state = 0
            score = like * self.template_probs_[ids]
        best = int(np.argmax(score))
        j = int(ends[best])
        nxt = int(self.vlmm_.transition(np.array([state]), np.array([j]))[0])
        return self.template(ids[best])[taus[best] :], nxt, j

    def predict_configurations(
        self,
        features: np.ndarray,
        prepared: list[tuple[np.ndarray, int, int]] | dict[int, tuple[np.ndarray, int, int]],
        frames: np.ndarray,
        horizon: int,
        n_samples: int,
        rng: np.random.Generator | None,
    ) -> np.ndarray:
        """(len(frames), n_samples, horizon, d): the rest of the matched template, then keys."""
        base = self.prototype_model_
        frames = np.asarray(frames)
        c0, dc0 = base.start_knots(features, frames, n_samples)
        paths = []
        for n, t in enumerate(frames):
            remaining, state, key = prepared[t]
            for s in range(n_samples):
                tokens = [int(v) for v in remaining] or [int(self.keys_[key])]
                c, dc = base.knots(np.array(tokens[:1]))
                row = n * n_samples + s
                time = float(
                    base.intervals(np.stack([c0[row], c[0]]), np.stack([dc0[row], dc[0]]))[0]
                )
                time += float(base.pair_intervals[tokens[:-1], tokens[1:]].sum())
                paths.append(self._expand(key, state, tokens, time, horizon, rng))
        width = max(len(p) for p in paths)
        padded = np.array([p + [p[-1]] * (width - len(p)) for p in paths])
        out = base.continuation(padded, c0, dc0, horizon)
        return out.reshape(len(frames), n_samples, horizon, base.n_dims)

    def predict(
        self,
        motion: Motion,
        seconds: float,
        rng: np.random.Generator | None = None,
        stochastic: bool = False,
    ) -> Motion:
        """The observed motion (at the model's frame rate) followed by ``seconds`` of
        predicted continuation: the most likely one, or drawn when ``stochastic``."""
        base = self.prototype_model_
        feats = self.observe([motion])[0]
        horizon = int(round(seconds * self.fps))
        last = np.array([len(feats) - 1])
        rng = call_rng(rng, stochastic, self.random_state)
        prepared = self.prepare(feats, last)
        pred = self.predict_configurations(feats, prepared, last, horizon, 1, rng)
        return base.to_motion(np.vstack([feats[:, : base.n_dims], pred[0, 0]]))

    # ------------------------------------------------- shared with the base
    @property
    def fps(self) -> float:
        return self.prototype_model_.fps

    @property
    def n_dims(self) -> int:
        return self.prototype_model_.n_dims

    @property
    def skeleton_(self):
        return self.prototype_model_.skeleton_

    @property
    def marker_names(self) -> tuple[str, ...]:
        return self.prototype_model_.marker_names

    def fits(self, take) -> bool:
        """Whether the model can observe ``take`` (:meth:`BehaviourModel.fits`)."""
        return self.prototype_model_.fits(take)

    def why_not(self, take, what: str = "the take") -> str:
        """Why :meth:`fits` refuses ``take`` (the prototype model's words)."""
        return self.prototype_model_.why_not(take, what)

    def observe(self, motions: Sequence[Motion]) -> list[np.ndarray]:
        return self.prototype_model_.observe(motions)

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray:
        return self.prototype_model_.configuration_positions(configs)

    # ---------------------------------------------------------------- score
    def key_tokens(self, motion: Motion) -> np.ndarray:
        """The key-prototype sequence (key indices) a motion passes through (§4.1)."""
        tokens = self.prototype_model_.tokens(motion)
        key_index = np.full(len(self.prototype_model_.prototypes_), -1)
        key_index[self.keys_] = np.arange(len(self.keys_))
        return key_index[tokens[key_positions(tokens, self.keys_)]]

    def score(self, motions: Sequence[Motion]) -> float:
        """Log-likelihood (nats) of the motions' key-prototype sequences under the key VLMM,
        summed over the motions. The templates between keys are matched by DTW, not
        scored, so this is the likelihood of the sequence of keys only; the prototype
        model's :meth:`~BehaviourModel.score` scores every prototype."""
        return float(sum(self.vlmm_.log_likelihood(self.key_tokens(m)) for m in motions))
