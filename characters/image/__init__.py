"""2D image puppets: `ImagePuppet` (runtime, in `puppet`) and the parts it is built from.

- background.py: loading pictures as they come (EXIF, 16-bit, palette, CMYK); picture ->
  character mask and feathered alpha: the picture's own alpha, a flat colour key, or the light
  field; a drawing's outline filled; largest component, hole filling; large pictures analysed
  on a smaller copy, the mask returned at full size
- light.py: the background as a smooth light field fitted robustly to the border, residual
  threshold, shadows on the background, GrabCut edge refinement
- drawing.py: pen drawings: ink out to half its contrast, small gaps closed, outline filled
- skeleton.py: automatic pins: the silhouette's skeleton, limb tips and a body anchor
- mesh.py: mask -> contour -> regular grid triangle mesh (even-odd rule + border cells), springs
- arap.py: two-step as-rigid-as-possible deformation (Igarashi et al. 2005), factorised per pin set
- guard.py: a constraint that keeps mass-spring triangles from folding over
- bake.py: keyframe baking and linear-blend playback, with the deviation it costs
- puppet.py: `ImagePuppet`, which composes them

Building needs OpenCV (pip install 'mop[image]'); everything else is NumPy, SciPy and numba.
The sample picture and its generator are in `characters.assets` (momo).
"""

import lazy_loader

# the runtime is imported when first asked for, so that a builder module stays light
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "puppet": ["ImagePuppet", "PuppetMode", "Pin"],
})
