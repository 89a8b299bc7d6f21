"""A tiny MassSpring-based stand-in puppet for session tests (tests only, not package code).

A 2D strip of nodes: the first two are fixed, each named target pulls one node towards a
position [px] with a target spring. It follows the shared puppet interface exactly."""
import numpy as np

from characters import Control, MassSpring, Verlet


class StripPuppet:
    def __init__(self, names=("tip",), *, nodes=6, spacing=10.0, stiffness=400.0):
        x = np.stack([np.arange(nodes) * spacing, np.zeros(nodes)], axis=1)
        rows = np.vstack([x, x + (0.0, spacing)])
        springs = [(i, i + 1) for i in range(nodes - 1)]
        springs += [(nodes + i, nodes + i + 1) for i in range(nodes - 1)]
        springs += [(i, nodes + i) for i in range(nodes)]
        springs += [(i, nodes + i + 1) for i in range(nodes - 1)]
        self.model = MassSpring(rows, np.array(springs), stiffness=stiffness, damping=0.5,
                                mass=0.05, velocity_damping=2.0, fixed=[0, nodes])
        self.state = self.model.state()
        self.integrator = Verlet(substeps=4)
        self.faces = np.array([(i, i + 1, nodes + i + 1) for i in range(nodes - 1)]
                              + [(i, nodes + i + 1, nodes + i) for i in range(nodes - 1)])
        self._nodes = {name: nodes - 1 - k for k, name in enumerate(names)}

    @property
    def target_names(self):
        return tuple(self._nodes)

    def reset(self):
        self.state = self.model.state()

    def step(self, dt, targets):
        pulls = {}
        for name, value in targets.items():
            if name not in self._nodes:
                raise ValueError(f"unknown target {name!r}; expected one of {self.target_names}")
            value = np.atleast_1d(np.asarray(value, dtype=float))
            node = self._nodes[name]
            # a scalar target bends the node up by that many spacings
            position = (self.model.rest_positions[node] + (0.0, 10.0 * value[0])
                        if value.size == 1 else value)
            pulls[node] = position
        control = Control(targets=pulls, target_stiffness=200.0, target_damping=2.0) if pulls \
            else None
        self.integrator.step(self.model, self.state, dt, control)

    def surface(self):
        return self.state.x
