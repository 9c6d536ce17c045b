"""Hidden Markov models: the Gaussian HMM and the dual HMM of the interaction paper.

``gaussian`` (hmmlearn-shaped ``GaussianHMM`` over the compiled recursions of
:mod:`markovmotion.algorithms.hmm_recursions`), ``dual`` (one chain, two
emission sets: the dual HMM, eqs. 1-2 of
``papers/dual-hmm-windowed-viterbi-interaction.txt``), ``trellis`` (§3.2's
generation of B's poses from real training frames) and ``partner`` (the
online partner: windowed Viterbi plus the trellis, frame by frame).
"""

from markovmotion.models.hmm.dual import DualHMM
from markovmotion.models.hmm.gaussian import GaussianHMM
from markovmotion.models.hmm.partner import Partner

__all__ = ["DualHMM", "GaussianHMM", "Partner"]
