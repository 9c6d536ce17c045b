"""Features: motion to model observations and back, as composable saved steps."""

from markovmotion.algorithms.mlpg import delta_matrix
from markovmotion.features.augmented import AugmentedConfiguration
from markovmotion.features.base import FeaturePipeline, FeatureStep
from markovmotion.features.body_motion import BodyMotion
from markovmotion.features.deltas import Deltas, add_deltas
from markovmotion.features.expmap import ExpMaps, continuous_rotvec
from markovmotion.features.pca import PCA
from markovmotion.features.positions import JointPositions
from markovmotion.features.smoothing import TemporalSmoothing

__all__ = [
    "PCA",
    "AugmentedConfiguration",
    "BodyMotion",
    "Deltas",
    "ExpMaps",
    "FeaturePipeline",
    "FeatureStep",
    "JointPositions",
    "TemporalSmoothing",
    "add_deltas",
    "continuous_rotvec",
    "delta_matrix",
]
