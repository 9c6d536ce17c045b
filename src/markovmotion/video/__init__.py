"""Video for the interaction model (interaction paper, §2 and §5).

``render`` draws motion capture as filled silhouettes from a fixed side camera,
``tracker`` finds people in video by background subtraction and outlines them
with closed B-splines (``bspline``), ``dataset`` renders and tracks the
two-person takes, ``partner`` draws the virtual partner into video.
"""
