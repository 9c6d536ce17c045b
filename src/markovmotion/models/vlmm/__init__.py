"""Variable-length Markov models of behaviour (``papers/vlmm-behaviour-models.txt``).

``prediction_suffix_tree`` (the VLMM itself, §2.3), ``behaviour`` (prototypes
of augmented configuration vectors and the VLMM over them: generation and
prediction, §2.1-2.4) and ``structured`` (the two-level model: key prototypes,
atomic-behaviour templates by DTW, a VLMM over keys, §2.5).
"""

from markovmotion.models.vlmm.behaviour import BehaviourModel, fit_index
from markovmotion.models.vlmm.prediction_suffix_tree import VLMM
from markovmotion.models.vlmm.structured import StructuredBehaviourModel, load_behaviour

__all__ = ["VLMM", "BehaviourModel", "StructuredBehaviourModel", "fit_index", "load_behaviour"]
