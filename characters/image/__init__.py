"""The parts of an image puppet (characters.ImagePuppet lives in characters/image_puppet.py):

- background.py: picture -> character mask and feathered alpha (corner colour + tolerance, or
  the picture's own alpha), largest component, hole filling
- mesh.py: mask -> contour -> regular grid triangle mesh (even-odd rule + border cells), springs
- arap.py: two-step as-rigid-as-possible deformation (Igarashi et al. 2005), factorised per pin set
- guard.py: a constraint that keeps mass-spring triangles from folding over
- bake.py: keyframe baking and linear-blend playback, with the deviation it costs

Building needs OpenCV (pip install 'mop[image]'); everything else is NumPy, SciPy and numba.
"""
