"""Video in and out: silhouettes for the interaction model (interaction paper, §2 and §5), and
multi-view video, 3-D tracking and compositing for the dual HMM (dual-HMM paper, §3).

``render`` draws motion capture as filled silhouettes from a fixed side camera,
``tracker`` finds people in video by background subtraction and outlines them
with closed B-splines (``bspline``), ``dataset`` renders and tracks the
two-person takes, ``partner`` draws the virtual partner into video,
``contours`` renders and tracks one person's exercise takes into the contour
configurations of the VLMM paper's data set 1 (§2.1.1).

``cameras`` holds calibrated cameras and ``cameras.json``; ``body_model`` the
articulated body tracked in 3-D; ``shading`` shaded bodies with depth;
``multiview`` renders takes seen by several cameras and measures tracking;
``annealed_particle_filter`` tracks a person in 3-D (Deutscher et al.);
``composite`` draws the dual HMM's partner into the tracked video.
"""

import os

#: FFmpeg's own log lines (a broken file's "moov atom not found", a damaged frame's "Invalid NAL
#: unit size") held back, so that a bad video gets our one line: OpenCV reads this when it first
#: opens a video, so it is set here, before any module of the package opens one (the camera
#: file's reading opens each video for its frame rate; set in ``render`` alone, a damaged
#: video's log reached the particle filter's terminal). A user's own setting is kept.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
