"""The behaviour chain and its CONDENSATION partner (``papers/interaction-behaviour-condensation.txt``).

``behaviour_chain`` (state prototypes, behaviour vectors by a decaying memory,
behaviour prototypes, the Markov chain over them and Hermite extrapolation,
§§3-4), ``condensation`` (single- and multiple-hypothesis propagation, §5) and
``partner`` (the virtual partner on 3-D joint-shape vectors or silhouettes).
"""

from markovmotion.models.chain.partner import ChainPartner, VirtualPartner

__all__ = ["ChainPartner", "VirtualPartner"]
