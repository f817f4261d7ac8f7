"""
Device drivers, device emulators and the simulated world.

Dobot Magician and servo-controller drivers over pyserial, byte-exact device emulators on
pseudo-terminals, and the simulated world; nodes dobot_driver, servo_driver, sim_world.
"""
