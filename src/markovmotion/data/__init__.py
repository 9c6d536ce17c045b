"""Access to the motion-capture collection (CMU, Bandai Namco) described by an INDEX.csv."""

from markovmotion.data.index import Entry, MocapIndex, candidate_roots, data_root

__all__ = ["Entry", "MocapIndex", "candidate_roots", "data_root"]
