"""Rendering: puppets to RGBA frames (2D image puppets, 3D scenes) and frame composition."""
