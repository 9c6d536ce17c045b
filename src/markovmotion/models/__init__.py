"""The models of the four papers, one package per family, on one contract.

``base`` (:class:`Model`: fit / save / load / the verbs, the ``KIND``
registry, ``train_files_``), ``online`` (the online partner protocol),
``hmm`` (Gaussian and dual HMMs), ``vlmm`` (variable-length Markov models of
behaviour), ``gait`` (HSMM gait synthesis and adaptation), ``chain``
(behaviour chain and CONDENSATION partner). Importing this package registers
every family's ``KIND``, so ``Model.load(path)`` reads a model of any kind.
"""

from markovmotion.models.base import KINDS, Model
from markovmotion.models.chain import VirtualPartner
from markovmotion.models.gait import GaitSynthesizer
from markovmotion.models.hmm import DualHMM
from markovmotion.models.vlmm import BehaviourModel, StructuredBehaviourModel

__all__ = [
    "KINDS",
    "BehaviourModel",
    "DualHMM",
    "GaitSynthesizer",
    "Model",
    "StructuredBehaviourModel",
    "VirtualPartner",
]
