"""The shipped characters and the scripts that generate them (deterministic, license-clean).

- `froggy.py` -> froggy.ply, froggy.json: the latex hand-puppet frog head and its finger regions
  (`python -m characters.assets.froggy`; needs manifold3d and trimesh);
- `caterpillar.py` -> medial_caterpillar.obj, .joints.json, .motion.json: the medial creature,
  its joints and a demo clip (`python -m characters.assets.caterpillar [DIR]`);
- `momo.py` -> momo.png, momo.pins.json, momo_wave.json: the image-puppet sample picture, its
  pins and a waving loop (`python -m characters.assets.momo`; needs Pillow).

The puppet kinds read these files by path (`LatexPuppet.froggy()`, `MedialObject.shipped()`);
nothing in the kinds imports a generator. The demo's takes are generated beside them, in
`recordings/make_demo_takes.py`, because takes are the application's format (`mop.takes`).
"""
