"""Rigid-body dynamics: bodies, penalty contact forces (Eq. 16–17), symplectic integration,
energy accounting and time-step control.  See :mod:`nurbsdem.dynamics.system` for the API."""
from __future__ import annotations

from .analytic_contact import SpherePlaneProvider, sphere_inertia
from ..contact.contactset import ContactSet
from .energy import EnergyLedger, EnergySample
from .forces import ContactLaw, InterfaceTable
from .rigid import PrescribedMotion, RigidBodies, Walls, principal_frame
from .stepcontrol import critical_step
from .system import DemSystem, InstabilityError, Kinematics

__all__ = ["DemSystem", "InstabilityError", "Kinematics", "critical_step", "ContactLaw",
           "InterfaceTable", "PrescribedMotion", "RigidBodies", "Walls", "principal_frame",
           "EnergySample", "EnergyLedger", "SpherePlaneProvider", "ContactSet",
           "sphere_inertia"]
