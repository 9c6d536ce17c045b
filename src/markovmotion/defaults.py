"""Defaults that the command line shows in its help, kept out of the model packages.

Typer reads an option's default when a command is defined, so these live in a module
that imports nothing: ``markovmotion --help`` lists every command without importing a
model, scikit-learn or numba. The models import them from here.
"""

from __future__ import annotations

#: Where the behaviour chain's two-person takes come from: 3-D motion capture or
#: tracked silhouettes.
SOURCES = ("mocap", "silhouette")

# The behaviour chain and its CONDENSATION partner (models/chain/condensation.py).
RESPONSES = ("ml", "map", "mean")
#: The response of :class:`MultipleHypotheses` unless told: the paper's maximum-likelihood
#: hypothesis. With the default 40 + 40 prototypes it beats the weighted mean by
#: leave-one-take-out over the eight salsa training takes (99.7 against 100.9 mm in 3-D;
#: with 300 + 300 the weighted mean was ahead, 98.2 against 101.2; see the README).
DEFAULT_RESPONSE = "ml"
#: sigma of the likelihood (eq. 20) unless told. The paper's 0.05 (for its
#: handshake silhouettes) collapses the 200 salsa hypotheses onto one lineage,
#: so the weighted mean is barely more than the ML hypothesis; 0.15 was the best
#: of 0.05-1 by leave-one-take-out over the eight salsa training takes in 3-D
#: (see the README), and no worse on silhouettes.
DEFAULT_SIGMA = 0.15
#: Re-synchronisation margin of :class:`SingleHypothesis` unless told (inf: never, the
#: paper's scheme). 0 (re-enter whenever a fresh chain state matches better) was the best
#: of 0, 0.02, 0.05, 0.1 and inf by leave-one-take-out over the eight salsa training takes.
DEFAULT_RESYNC = 0.0

# The behaviour chain's virtual partner (models/chain/partner.py).
#: State and behaviour prototypes unless told. The paper's 300 each (for its handshakes)
#: give partners that lose to the mean shape on the eight salsa training takes; 40 each
#: was the best of 20-300 by leave-one-take-out over them (see the README).
DEFAULT_PROTOTYPES = 40
#: Frames over which a 3-D partner's place in the world (reference point and heading) is
#: averaged, causally, unless told (1: not at all, the paper's). 20 (0.8 s at 25 fps) was
#: the best of 1-40 by leave-one-take-out over the eight salsa training takes (world error
#: of 200 hypotheses, ML: 557.2 mm at 1, 510.9 at 20, 511.5 at 25; the partner's jump p90
#: 402 to 66 mm, the real partner's 38; docs/chain.md, ``benchmarks/chain_place_window.py``).
DEFAULT_PLACE_WINDOW = 20

# The dual HMM's presets (``dualhmm train/crossval --preset``; models/hmm/dual.py).
#: The partner for people the model has never seen (docs/hmm.md, "New people"), as
#: :class:`DualHMM` parameters: A's heading as the frame, the person normalisation and
#: ``place_memory`` 300, fixed on principle; B's output by regression, PCA energy 0.99 and the
#: hands' contact at 1, the collection's picks by leaving one pair of people out. With
#: :data:`NEW_PEOPLE_ROLES`: ``DualHMM(**NEW_PEOPLE)`` fitted on every take in both roles.
NEW_PEOPLE: dict[str, object] = {
    "frame": "heading",
    "normalise": "person",
    "output": "regression",
    "place_memory": 300,
    "energy": 0.99,
    "contact_weight": 1.0,
}
#: The takes the partner for new people learns: each also with the people swapped.
NEW_PEOPLE_ROLES = "both"
#: ``--preset``: option values it sets where the command line leaves them at their defaults
#: ("paper": none, the paper's model).
DUALHMM_PRESETS: dict[str, dict[str, object]] = {
    "paper": {},
    "new-people": {"roles": NEW_PEOPLE_ROLES, **NEW_PEOPLE},
}

# The behaviour chain's presets (``chain train/crossval --preset``; models/chain/partner.py).
#: The chain's partner for people it has never seen (docs/chain.md, "New people"), as
#: :class:`VirtualPartner` parameters: the person normalisation, fixed on principle as the
#: dual HMM's, and the shape pulled half way to the training people's mean shape (the
#: collection's pick by leaving one pair of people out; nested, the folds chose 0.25-0.75).
#: Learnt in both roles (:data:`NEW_PEOPLE_ROLES`).
CHAIN_NEW_PEOPLE: dict[str, object] = {"normalise": "person", "shrink": 0.5}
#: ``chain train/crossval --preset``, as :data:`DUALHMM_PRESETS`.
CHAIN_PRESETS: dict[str, dict[str, object]] = {
    "paper": {},
    "new-people": {"roles": NEW_PEOPLE_ROLES, **CHAIN_NEW_PEOPLE},
}

# Multi-view video (video/cameras.py, the command line's --views).
#: Most cameras a camera file may hold. Making MediaPipe's left and right agree across the
#: views tries every labelling of them (2^(V-1)), each triangulated robustly over every
#: subset of views (2^V): 200 synthetic frames took 6 s at 4 views, 25 s at 5 and 170 s at
#: 6, and would take about an hour at 8 (``video.triangulation.views_sides``).
MAX_CAMERAS = 6
#: How ``track`` and ``dualhmm respond --video`` follow person A (``--method``; resolved in
#: ``video.multiview.resolve_method``). Here, not in ``video.multiview``, so that the option's
#: choices are known without importing the trackers (and with them scikit-learn and numba).
TRACK_METHODS = ("auto", "apf", "triangulate", "monocular")
