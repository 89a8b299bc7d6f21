"""Cameras and video files through OpenCV, with trackers that turn images into channels."""
from .base import Tracker
from .trackers import (ArucoTracker, ColorBlobTracker, FaceMeshTracker, HaarFaceTracker,
                       HandsTracker, PoseTracker, SilhouetteTracker, make_tracker,
                       tracker_names)

__all__ = ["ArucoTracker", "ColorBlobTracker", "FaceMeshTracker", "HaarFaceTracker",
           "HandsTracker", "PoseTracker", "SilhouetteTracker", "Tracker", "make_tracker",
           "tracker_names"]
