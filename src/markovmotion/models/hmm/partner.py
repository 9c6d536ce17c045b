"""The dual HMM's online virtual partner: one frame of A in, one frame of B out, ``lag`` late.

Windowed Viterbi (§3.1 of ``papers/dual-hmm-windowed-viterbi-interaction.txt``,
:mod:`markovmotion.algorithms.windowed_viterbi`) decides A's states one
slice at a time; the trellis of §3.2 (:mod:`.trellis`) picks B's frames. The
partner follows the online protocol of :mod:`markovmotion.models.online`
(``step``, ``skip``, ``finish``, ``lag``, ``fps``, ``skeleton``), so the
real-time replay (``dualhmm respond --realtime``) and the ``/live`` page
take it like any other online partner. It is made by
:meth:`DualHMM.partner <markovmotion.models.hmm.dual.DualHMM.partner>` and
takes the model as an argument (this module does not import the model's).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from markovmotion.algorithms.gaussian import gaussian_log_density, precision_cholesky
from markovmotion.algorithms.windowed_viterbi import WindowedViterbi, start_distribution
from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.features import BodyMotion
from markovmotion.features.body_motion import mean_place, place_rows
from markovmotion.features.markers import Lift, MarkerFeatures
from markovmotion.features.person import OnlineCentre, OnlineSizeScale, RunningCentre, body_radius
from markovmotion.models.base import finite_frames
from markovmotion.models.hmm.contact import OnlineContact
from markovmotion.models.hmm.gaussian import safe_log
from markovmotion.models.hmm.trellis import blend_positions
from markovmotion.models.online import FINISHED, CheckedOnce, MissingFrames, check_frame

if TYPE_CHECKING:
    from markovmotion.models.hmm.dual import DualHMM


@dataclass(frozen=True)
class SeenA:
    """Person A's whole motion as the partner sees it, computed at once for a stream that
    plays it frame by frame (:meth:`Partner.see`): what :meth:`Partner.step` computes for
    one frame, for all of them in a few vectorised calls, as :meth:`DualHMM.respond` does.

    Attributes:
        log_b: (F, N) log emission probabilities log b_j(x_t) of A's features under
            lambda_A's states (eq. 1's b_j), frame by frame.
        features: per frame A's features (Da,), or None for a missing frame (NaN).
        origin: (F, 3) where A stands (mm), B is placed by it.
        yaw: (F,) A's heading (radians).
        points: (F, P, 3) A's compared points for ``contact_weight`` (NaN where missing),
            else None.
    """

    log_b: np.ndarray
    features: list[np.ndarray | None]
    origin: np.ndarray
    yaw: np.ndarray
    points: np.ndarray | None = None


class Partner:
    """The virtual partner online: one frame of A in, one frame of B out, ``lag`` frames late.

    ``lag = window - 1`` frames (0.30 s at 30 fps with the paper's window of
    10). When frame t + lag arrives, the windowed decoder's latest slice
    covers frames t .. t + lag: its q_1 is frame t's state, decided (§3.1),
    the rest are that slice's best path. B's frame for t is the first step of
    the lowest-error trellis path (§3.2) over the slice, starting from the B
    frame shown last: the trellis run the windowed way, as §3.1 runs Viterbi,
    so it looks as far ahead as the decoder; B's place relative to A is
    averaged over the frames shown last and the path ahead
    (``placement_window``). :meth:`step` returns None until the first B frame
    is due; :meth:`finish` returns the last ``lag`` frames.
    A frame that is None or holds NaN is a missing observation: a warning,
    and the partner goes on from the dynamics alone.

    Attributes:
        lag: frames B trails A (``window - 1``).
        fps: the model's rate (A must come at it).
        skeleton: B's skeleton (of the frames :meth:`step` returns).
    """

    def __init__(self, model: DualHMM, window: int):
        self.model = model
        hmm = model.lambda_a_
        start = start_distribution(safe_log(hmm.startprob_), model.initial)
        self.decoder = WindowedViterbi(start, safe_log(hmm.transmat_), window)
        self.lag = window - 1
        self.fps = float(model.fps)
        self._trellis = model._trellis()
        prec, log_det = precision_cholesky(hmm.covars_)
        self._emission = (hmm.means_, prec, log_det)
        self._slice: deque = deque(maxlen=window)  # (A's features or None, columns by state)
        self._half = min(model.placement_window // 2, self.lag)
        self._before = max(self._half, int(getattr(model, "place_memory", 0)))
        # where A stood in the slice's frames and the ``before`` (place_memory) before them:
        # a ring of place_rows (origin (3), cos yaw, sin yaw) and of the yaws themselves
        self._places = np.zeros((window + self._before, 5))
        self._yaws = np.zeros(window + self._before)
        self._seen_at = np.zeros(window + self._before)  # 1: A seen in the frame, 0: held
        self._places_in = 0
        self._seen_a = False  # whether A has been seen (a place of A's own has come in)
        self._shown_count = 0
        self._blend = min(model.blend_window // 2, self.lag)
        keep = max(self._half, self._blend, 1)
        self._history: deque = deque(maxlen=keep)  # B's training frames shown
        self._generated: deque = deque(maxlen=keep)  # output="regression": B's markers shown
        self._frames_in = 0
        self._missed = MissingFrames()  # frames of A missing or NaN (the first logged)
        self._finished = False
        self._place = (np.zeros(3), 0.0)
        self._checked = CheckedOnce(model.check_input)  # A against the model, once a kind
        self._lift: Lift | None = None  # a skeleton's points lifted to the model's markers
        self._held = model.held() if model.uses_markers else None  # A's markers' short gaps
        self._lifted = 0.0  # the last frame's lift (mm)
        self._last: tuple | None = None  # A's last finite frame (pose, origin, yaw), for its motion
        self._centre: OnlineCentre | None = None  # A's running mean (normalise="person")
        self._size: OnlineSizeScale | None = None  # B's place scaled by A's size (place_scale)
        if getattr(model, "place_scale", "none") == "size":
            self._size = OnlineSizeScale(model.place_size_)
        self._unseen = np.zeros(len(hmm.means_))  # log b_j of a missing frame: no evidence
        # contact_weight: A's compared points per frame (a ring beside the places; NaN: not
        # seen) and the running mean of the contact's shifts (DualHMM.respond's, online)
        self._contact = model.contact
        if self._contact is not None:
            points = len(model.compared_names())
            self._a_points = np.full((len(self._places), points, 3), np.nan)
            self._moves = OnlineContact(float(model.contact_weight), model.contact_memory)

    @property
    def skeleton(self) -> Skeleton | None:
        """B's skeleton (None for a model on markers: its frames are Markers)."""
        return getattr(self.model, "skeleton_b_", None)

    def step_features(
        self, xa: np.ndarray | None, place: tuple[np.ndarray, float]
    ) -> tuple[int, np.ndarray, np.ndarray] | None:
        """Feed A's features (None: missing) and place (origin, yaw); for the frame ``lag``
        frames ago, once one is due, B's training frame and B's root in A's ground frame."""
        if xa is None:
            log_b = self._unseen
        else:
            log_b = gaussian_log_density(xa[None], *self._emission)[0]
        self._add_place(place, seen=xa is not None)
        return self.step_log_frameprob(log_b, xa)

    def _add_place(self, place: tuple[np.ndarray, float], seen: bool = False) -> None:
        """A's place for the next frame into the ring (``seen``: A's own, not a missing
        frame's). A's first place is also where A stood in the frames before it, as
        :meth:`DualHMM.respond` fills them: a stream that starts with A missing (a camera that
        sees no one yet) had averaged the origin into A's place for ``place_memory`` frames
        after A appeared (a partner 1.9 m off at A's first frame, 145 mm off 8 s later)."""
        if seen and not self._seen_a:
            self._seen_a = True
            self._places[:] = place_rows(np.asarray(place[0])[None], [place[1]])
            self._yaws[:] = place[1]
        i = self._places_in % len(self._places)
        row = self._places[i]  # place_rows's layout, by hand: the live step's hot path
        row[:3], row[3], row[4] = place[0], math.cos(place[1]), math.sin(place[1])
        self._yaws[i] = place[1]
        self._seen_at[i] = 1.0 if seen else 0.0
        if self._contact is not None:  # A's points unseen until _see_points says otherwise
            self._a_points[self._places_in % len(self._places)] = np.nan
        self._places_in += 1

    def _see_points(self, points: np.ndarray) -> None:
        """A's compared points (P, 3) of the frame just added (``contact_weight``)."""
        if self._contact is not None:
            self._a_points[(self._places_in - 1) % len(self._places)] = points

    def step_log_frameprob(
        self, log_b: np.ndarray, xa: np.ndarray | None
    ) -> tuple[int, np.ndarray, np.ndarray] | None:
        """:meth:`step_features` from A's log emission probabilities (N,), already computed."""
        if not self._advance(log_b, xa):
            return None
        states = self.decoder.path
        if self.model.output == "regression":
            return self._regress(states, list(self._slice), 1)[0]
        states = states.tolist()  # Python ints: the slice's caches are keyed by them
        cols = self._columns(states, self._slice)
        path = self._trellis.best_path(states, cols, self._shown, self._steps(states, cols))
        return self._show(path, 1)[0]

    def _advance(self, log_b: np.ndarray, xa: np.ndarray | None) -> bool:
        """One frame into the slice and the windowed decoder; whether a B frame is due."""
        self._slice.append((xa, {}))
        self.decoder.push(log_b)
        self._frames_in += 1
        return self._frames_in > self.lag

    @property
    def _shown(self) -> int | None:
        """B's training frame shown last."""
        return self._history[-1] if self._history else None

    def _show(self, path: np.ndarray, count: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Show the first ``count`` B frames of ``path``, each with its averaged place and
        its blended rotations (over the frames shown last and the path ahead)."""
        shown = list(self._history)
        roots = self._trellis.placement(path, self._half, shown[len(shown) - self._half :], count)
        rots = self._trellis.blend(path, self._blend, shown[len(shown) - self._blend :], count)
        self._history.extend(int(i) for i in path[:count])
        return list(zip(path[:count].tolist(), roots[:count], rots[:count], strict=True))

    def finish_frames(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """B's training frames and places still owed at the end of the stream."""
        if self._frames_in == 0:
            return []
        entries = list(self._slice)
        if self._frames_in < self.decoder.window:
            states = self.decoder.flush()
        else:
            states, entries = list(self.decoder.path[1:]), entries[1:]
        if not entries:
            return []
        if self.model.output == "regression":
            return self._regress(states, entries, len(entries))
        path = self._trellis.best_path(states, self._columns(states, entries), self._shown)
        return self._show(path, len(path))

    def _regress(
        self, states: Sequence[int], entries: Sequence[tuple], count: int
    ) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """``output="regression"``: B's generated markers for the slice's frames, the first
        ``count`` shown, each blended with those shown before and the slice ahead (as
        :meth:`DualHMM.respond` blends the whole stream)."""
        rel = self.model.regression_positions(states, [x for x, _ in entries])
        before = np.array(self._generated).reshape(-1, *rel.shape[1:])
        frames = np.concatenate([before, rel])
        t = np.arange(len(before), len(before) + count)
        root, rot = blend_positions(frames, t, self._blend)
        self._generated.extend(rel[:count])
        return [(0, r, s) for r, s in zip(root, rot, strict=True)]

    def _columns(self, states: Sequence[int], entries: Sequence[tuple]) -> list[tuple]:
        cols = []
        for q, (xa, cache) in zip(states, entries, strict=True):
            if q not in cache:
                cache[q] = self._trellis.candidates(q, xa)
            cols.append(cache[q])
        return cols

    def _steps(self, states: Sequence[int], cols: list[tuple]) -> list[np.ndarray]:
        """Distances between consecutive columns of the slice, each computed once per pair of
        states (a slice shares all but its last column with the one before)."""
        out = []
        for t in range(1, len(cols)):
            cache = self._slice[t][1]
            key = (states[t], states[t - 1])
            if key not in cache:
                cache[key] = self._trellis.distances(states[t], cols[t][0], cols[t - 1][0])
            out.append(cache[key])
        return out

    def step(self, frame: Motion | Markers | None) -> Motion | Markers | None:
        """One frame of A (a one-frame Motion, or for a model on markers one-frame Markers
        or a Motion to place virtual markers on) in; B's frame of ``lag`` frames ago out.
        Not one frame, or at another rate than the partner's, or after :meth:`finish`: a
        ValueError (:func:`check_frame`). A missing frame (None, or NaN) is skipped, with a
        logged warning (once per stream)."""
        if self._finished:
            raise ValueError(FINISHED)
        if frame is not None:
            check_frame(frame, self.fps)
            self._checked(frame)
        if frame is not None and self.model.uses_markers:
            lifting = self.model.lifts(frame)
            frame = self._held.step(self.model.input_markers(frame))
            if lifting:  # a skeleton's body points to a model of sensor markers: DualHMM.a_in
                self._lift = self._lift or self.model.lift()
                frame, self._lifted = self._lift.step(frame)
        if frame is None or not finite_frames(frame)[0]:
            self._missed(self._frames_in)
            return self.skip()
        if isinstance(frame, Markers):
            pos = frame.positions
            if self._size is not None:
                self._size(body_radius(pos)[0])
            origin, yaw = self.model.place(frame)
            origin[:, 1] -= self._lifted
        else:
            pos = frame.positions()
            origin, yaw = self.model.ground(frame, pos)
        self._place = (origin[0], float(yaw[0]))
        shown = self.step_features(self._features(frame, pos, origin, yaw), self._place)
        if self._contact is not None:  # a Motion's joint positions are computed already
            known = None if isinstance(frame, Markers) else pos
            self._see_points(self.model.body_positions(frame, positions=known)[0])
        return self._motion(shown)

    def _features(
        self, frame: Motion | Markers, pos: np.ndarray, origin: np.ndarray, yaw: np.ndarray
    ) -> np.ndarray:
        """A's model features of ``frame`` from its joint (marker) positions and ground
        frame: with A's motion in the observation, :meth:`BodyMotion.rows` of the last
        finite frame and this one (what :meth:`DualHMM.features_a` gives for this frame of
        the whole stream)."""
        first, *rest = self.model.pipeline_a_.steps
        if not isinstance(first, BodyMotion | MarkerFeatures) or not getattr(first, "motion", True):
            x = first.transform([frame])[0]
        else:
            now = (first.pose(frame, pos), origin, yaw)
            last, self._last = self._last, now
            if last is not None:
                now = tuple(np.concatenate(p) for p in zip(last, now, strict=True))
            # only this frame's row goes on: the steps after the first are row by row (PCA)
            # or kept across frames (the running centre), so A's features of a frame are
            # computed once, when it arrives
            x = first.rows(*now, frame.fps)[-1:]
        for step in rest:
            if isinstance(step, RunningCentre):  # A's running mean: kept across frames
                self._centre = self._centre or step.online()
                x = self._centre(x[-1])[None]
            else:
                x = step.transform([x])[0]
        return x[-1]

    def see(self, motion: Motion | Markers) -> SeenA | None:
        """Person A's whole ``motion`` (at the model's rate) seen at once, for callers that
        stream it frame by frame (the live page, looping; read-only, so the partners of
        several sessions may share it): :meth:`step_seen` then costs the
        decoder, the trellis and B, not A's forward kinematics, features and densities
        (:meth:`DualHMM.features_a` over the motion, as :meth:`DualHMM.respond` computes
        them). None for a model whose A features depend on the stream before the motion
        (the running centre of ``normalise="person"``, or A's running size of
        ``place_scale="size"``, kept across loops): step it frame by frame.

        Raises:
            SkeletonMismatchError: a motion the model cannot answer (``check_input``).
        """
        steps = self.model.pipeline_a_.steps
        if self._size is not None or any(isinstance(step, RunningCentre) for step in steps):
            return None
        self.model.check_input(motion)
        motion, lift = self.model.a_in(motion)
        xa, missing = self.model.features_a(motion)
        log_b = gaussian_log_density(xa, *self._emission)
        origin, yaw = self.model.place(motion)
        if lift is not None:
            origin[:, 1] -= lift
        for array in (xa, log_b, origin, yaw):  # shared by the sessions streaming the motion
            array.flags.writeable = False
        seen = [None if m else x for x, m in zip(xa, missing, strict=True)]
        points = None
        if self._contact is not None:
            points = self.model.body_positions(motion)
            points[missing] = np.nan
            points.flags.writeable = False
        return SeenA(log_b, seen, origin, yaw, points)

    def step_seen(self, seen: SeenA, t: int) -> Motion | Markers | None:
        """:meth:`step` for frame ``t`` of A's motion seen by :meth:`see` (a missing frame,
        NaN: :meth:`skip`, without a warning)."""
        if seen.features[t] is None:
            return self.skip()
        self._place = (seen.origin[t], float(seen.yaw[t]))
        self._add_place(self._place, seen=True)
        if seen.points is not None:
            self._see_points(seen.points[t])
        return self._motion(self.step_log_frameprob(seen.log_b[t], seen.features[t]))

    def skip(self) -> Motion | Markers | None:
        """A frame the caller could not deliver (dropped): no observation, no warning."""
        if self._finished:
            raise ValueError(FINISHED)
        return self._motion(self.step_features(None, self._place))

    def drop(self) -> None:
        """A frame a caller dropped and will not show B's answer for (a live session behind
        its clock): for the decoder a missing frame, as with :meth:`skip`, but B's frame for
        ``lag`` frames ago is not decided (no trellis, no placement), and the next B frame
        shown follows on from the last one shown. A decoder step, a tenth of a partner step,
        so a session that has fallen behind catches up at once."""
        if self._finished:
            raise ValueError(FINISHED)
        self._add_place(self._place)
        if self._advance(self._unseen, None):
            self._shown_count += 1
            if self._contact is not None:
                self._moves.step(np.full(3, np.nan))

    def finish(self) -> list[Motion | Markers]:
        """B's frames still owed at the end of the stream; the stream ends (a later
        :meth:`step`, :meth:`skip` or :meth:`drop` is a ValueError)."""
        if self._finished:
            raise ValueError(FINISHED)
        self._finished = True
        return [self._motion(shown) for shown in self.finish_frames()]

    def _place_of(self, frame: int) -> tuple[np.ndarray, float]:
        """A's place for B's frame ``frame`` of the stream, averaged over the frames around it
        that have arrived and show A (the one frame of
        :func:`~markovmotion.models.hmm.trellis.smooth_place`, as :meth:`DualHMM.respond`
        does); none: the frame's own (A's last place held)."""
        ring = len(self._places)
        lo = max(frame - self._before, self._places_in - ring, 0)
        hi = min(frame + self._half, self._places_in - 1)
        near = np.arange(lo, hi + 1) % ring
        weight = self._seen_at[near]
        total = weight.sum()
        if hi == lo or total == 0:
            return self._places[frame % ring, :3].copy(), float(self._yaws[frame % ring])
        origin, yaw = mean_place(weight @ self._places[near] / total)
        return origin, float(yaw)

    def _motion(self, shown: tuple[int, np.ndarray, np.ndarray] | None) -> Motion | Markers | None:
        """B's frame ``shown`` (training frame, root, rotations) placed by A's place for it."""
        if shown is None:
            return None
        origin, yaw = self._place_of(self._shown_count)
        root = shown[1][None]
        if self._size is not None:
            root = self.model.scaled_root(root, np.array([self._size.scale]))
        b = self.model.frames_to_motion(
            np.array([shown[0]]), origin[None], np.array([yaw]), root, shown[2][None]
        )
        if self._contact is not None:
            a = self._a_points[self._shown_count % len(self._places)][None]
            shift = self._contact.shifts(a, np.array([yaw]), self.model.body_positions(b))
            b = self.model.moved(b, self._moves.step(shift[0])[None])
        self._shown_count += 1
        return b
