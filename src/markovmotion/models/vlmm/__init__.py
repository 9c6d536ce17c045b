"""Variable-length Markov models of behaviour (``papers/vlmm-behaviour-models.txt``).

``prediction_suffix_tree`` (the VLMM itself, §2.3), ``behaviour`` (prototypes
of augmented configuration vectors and the VLMM over them: generation and
prediction, §2.1-2.4) and ``structured`` (the two-level model: key prototypes,
atomic-behaviour templates by DTW, a VLMM over keys, §2.5).
"""
