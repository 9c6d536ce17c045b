"""Shared algorithms, written once as pure functions and used by every model that needs them.

``hermite`` (cubic Hermite interpolation), ``vector_quantisation`` (prototypes,
tokens), ``dtw`` (dynamic time warping, open-end alignment),
``kinematics`` (batched forward kinematics from rotation vectors),
``hmm_recursions`` (compiled log-space forward, backward, Viterbi and
transition counts shared by the HMM variants, free of the GIL) and
``parallel`` (EM's per-sequence statistics mapped over joblib, and Dask through it).
"""
