"""The main job, ``markovmotion demo``: one module per family, each a demo step."""

from markovmotion.demo.run import run_demo

__all__ = ["run_demo"]
