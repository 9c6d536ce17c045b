"""Evaluation of synthesized and predicted motion (perceptual tests: :mod:`.perceptual`)."""
