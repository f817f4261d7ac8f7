"""
The simulated world, in a room of its own (SIMULATION.md).

Sun, clouds, Fresnel lens flux, wood heat and char, RGB and thermal cameras, a simulated
clock and the emulated devices on pseudo-terminals.

It stands at the outer edge of the system, where the real rig would be: the driver nodes
talk to its emulators over serial, the perception nodes see its images. Nothing here is
imported by device code (``helio_drivers`` outside ``sim``).
"""
