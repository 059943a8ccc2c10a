"""The follower-force rotor as a user system file: the source of the Hopf-point and oscillation tests.

The text is a user's file (``orbit --system FILE:build`` reads it from a temporary path) and is executed in-process by the
API tests, so every test holds the same system.
"""

import math

#: A rotationally symmetric oscillator under a saturating follower force, written as a user's system file.
ROTOR = """
import numpy as np
import scipy.sparse as sp

from cosserat_chain.systems.base import System

ROTATION = np.array([[0.0, -1.0], [1.0, 0.0]])
#: The full 2 x 2 pattern of a CSR matrix (column indices, row pointers): the Jacobian's entries are filled into it
#: directly, not converted from a dense array on each of the integrator's thousands of calls.
FULL_2X2 = (np.array([0, 1, 0, 1], dtype=np.int32), np.array([0, 2, 4], dtype=np.int32))


class FollowerRotor(System):
    '''A rotationally symmetric oscillator under a saturating follower (circulatory) force:

        q'' + c q' = -kk q + (a0 - b |q|^2) J q,        J the rotation by a quarter turn.

    The equilibrium q = 0 has the eigenvalues of lambda^2 + c lambda + kk -+ i a0 = 0: a Hopf point at
    a0 = c sqrt(kk), frequency sqrt(kk). The circle q = R (cos wt, sin wt) solves the equations where
    w^2 = kk and a0 - b R^2 = c w: orbits of period 2 pi / sqrt(kk) and radius sqrt((a0 - c sqrt(kk)) / b),
    born at the Hopf point (a Stuart-Landau normal form in second-order form).
    '''

    name = "follower-rotor"

    def __init__(self, **parameters):
        super().__init__({"a0": 0.3, "b": 1.0, "c": 0.2, "kk": 1.5, **parameters})

    @property
    def coordinates(self):
        return ("x", "y")

    @property
    def angles(self):
        return np.zeros(2, dtype=bool)

    def forces(self, q):
        p = self.parameters
        return -p["kk"] * q + (p["a0"] - p["b"] * (q @ q)) * (ROTATION @ q)

    def force_jacobian(self, q):
        p = self.parameters
        j = -p["kk"] * np.eye(2) + (p["a0"] - p["b"] * (q @ q)) * ROTATION - 2 * p["b"] * np.outer(ROTATION @ q, q)
        return sp.csr_matrix((j.ravel(), *FULL_2X2), shape=(2, 2))

    def parameter_forces(self, q, name):
        self._check_name(name)
        jq = ROTATION @ q
        return {"a0": jq, "b": -(q @ q) * jq, "kk": -q}.get(name, np.zeros(2))

    def mass(self):
        return np.ones(2)

    def damping(self):
        return np.full(2, self.parameters["c"])


def build(**parameters):
    return FollowerRotor(**parameters)
"""

#: Its closed forms at the default kk = 1.5, c = 0.2: the period of every orbit and the Hopf point a0 = c sqrt(kk).
PERIOD = 2 * math.pi / math.sqrt(1.5)
HOPF = 0.2 * math.sqrt(1.5)


def rotor_class():
    """The ``FollowerRotor`` class of :data:`ROTOR`, executed here."""
    namespace: dict = {}
    exec(ROTOR, namespace)
    return namespace["FollowerRotor"]
