"""Cameras and video files through OpenCV, with trackers that turn images into channels."""
from .trackers import (ArucoTracker, ColorBlobTracker, FaceTracker, HandTracker, Tracker,
                       make_tracker)

__all__ = ["ArucoTracker", "ColorBlobTracker", "FaceTracker", "HandTracker", "Tracker",
           "make_tracker"]
