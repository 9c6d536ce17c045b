"""Stylistic gait synthesis by HSMMs (``papers/hsmm-stylistic-gait-synthesis.txt``).

``hsmm`` (5-state left-to-right HSMMs with Gaussian durations over the
explicit-duration recursions of :mod:`markovmotion.algorithms.hsmm_recursions`),
``context_tree`` (decision-tree context clustering, MDL), ``adaptation``
(CMLLR / CSMAPLR then MAP, walker-adaptive training) and ``synthesizer``
(the average walk, its adaptation to a style, and MLPG synthesis).
"""

from markovmotion.models.gait.hsmm import HSMM
from markovmotion.models.gait.synthesizer import GaitSynthesizer

__all__ = ["HSMM", "GaitSynthesizer"]
