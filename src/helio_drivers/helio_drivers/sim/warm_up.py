"""
Compile the simulated world's numba kernels into their cache before anything runs the world.

    python -m helio_drivers.sim.warm_up        (scripts/setup.sh runs it after each build)

``sim_world`` also calls ``warm_up`` before it opens its emulated devices' ports: numba
loads a kernel's cached machine code only at its first call, and those loads, spread over
the first step and the first move, stalled the emulators too (below).

numba compiles a kernel at its first call and keeps the machine code beside ``kernels.py``
(``cache=True``); a fresh build copies ``kernels.py`` into ``install/`` and starts with an
empty cache. Compiling holds the interpreter lock for 5-8 s of a 2-core machine, and the
``sim_world`` node serves its emulated Dobot and Maestro from threads of the same process:
a world that compiled at its first step (or at the first move of the arm) left the drivers'
serial requests unanswered for longer than their 0.1 s timeouts, they reported the link
lost, and the first move of the graph failed ("servo controller not connected"). Here a
throwaway world heats a dot, moves the lens, and renders both cameras and the canvas, which
calls every kernel with the argument types the node uses; afterwards each process loads the
machine code from the cache (a few tens of milliseconds).
"""

import argparse
import time

from helio_drivers.sim import kernels
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.node_kit.process_tuning import single_threaded_numerics
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
import numba

DOT = (0.07, 0.07)          # world [m]
D_LP = 0.082                # heating distance [m]


def all_kernels():
    """
    Return the names of the public numba kernels of ``kernels``.

    The private ones (``_cell_of``...) are compiled into the public kernels that call them.
    """
    return sorted(name for name, value in vars(kernels).items()
                  if isinstance(value, numba.core.registry.CPUDispatcher)
                  and not name.startswith('_'))


def compiled_kernels():
    """Return the public kernels that have machine code in this process (compiled or loaded)."""
    return [name for name in all_kernels() if getattr(kernels, name).signatures]


def warm_up(rig=None, steps=10, settings=None, build=None):
    """
    Run a throwaway world through heating, a move and every render; return the kernels run.

    `steps` world steps are taken at the heating pose and again during the move; `settings`
    (SimSettings, default the defaults) and `build` (``sim.build.Build``, default the ideal
    build of `rig`) those of the world that will run, so that the kernels its settings and
    its cameras (with or without distortion) call are the ones made ready.
    """
    if build is None:
        world = SimWorld(settings or SimSettings(),
                         rig or load_rig_parameters(default_rig_file()))
    else:
        world = SimWorld(settings or SimSettings(), build=build)
    here = true_sun_focus_joints(world, DOT, D_LP)
    there = true_sun_focus_joints(world, (DOT[0] + 0.004, DOT[1]), D_LP)
    for joints in (here, there):
        world.set_joints(joints)
        for _ in range(steps):
            world.step()
        for _ in range(2):          # a new view, then the same view again (a kept sampler)
            world.thermal_image()
            world.rgb_image()
    world.canvas_image()
    return compiled_kernels()


def main(args=None):
    """Warm the cache; print how long it took and which kernels ran."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.parse_args(args)
    single_threaded_numerics()
    started = time.perf_counter()
    ran, every = warm_up(), all_kernels()
    missing = sorted(set(every) - set(ran))
    print(f'helio_drivers.sim.warm_up: {len(ran)} of {len(every)} kernels compiled or '
          f'loaded in {time.perf_counter() - started:.1f} s'
          + (f' (not run: {", ".join(missing)})' if missing else ''))


if __name__ == '__main__':
    main()
