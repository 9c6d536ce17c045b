"""The browser side of markovmotion: motion viewer, live partner, perceptual evaluation."""

from markovmotion.web.app import create_app
from markovmotion.web.library import MotionLibrary

__all__ = ["MotionLibrary", "create_app"]
