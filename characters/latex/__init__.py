"""Builders behind `characters.LatexPuppet`: surface loading and repair, decimation (paper 4.1),
internal layers (4.2), the connection map (equations 3-4), finger regions and the shipped frog.

Low modules first: `surface` (arrays in, arrays out; inside tests and distances), then
`decimate`, `layers`, `connection`, `regions`; `froggy` generates the shipped asset."""
