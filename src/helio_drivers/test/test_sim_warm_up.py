"""The warm-up that fills the numba cache after a build runs every kernel of the world."""

import json
import subprocess
import sys

from helio_drivers.sim import kernels
import numba

# in a fresh interpreter: this test process may have run the kernels in other tests already
PROBE = """
import json
from helio_drivers.sim import kernels
from helio_drivers.sim.warm_up import warm_up
before = [n for n, v in vars(kernels).items() if getattr(v, "signatures", None)]
ran = warm_up(steps=2)
after = [n for n, v in vars(kernels).items() if getattr(v, "signatures", None)]
print(json.dumps({"before": before, "ran": ran, "after": after}))
"""


def test_the_warm_up_runs_every_public_kernel_in_a_fresh_process():
    public = {name for name, value in vars(kernels).items()
              if isinstance(value, numba.core.registry.CPUDispatcher)
              and not name.startswith('_')}
    assert len(public) >= 10
    done = subprocess.run([sys.executable, '-c', PROBE], capture_output=True, text=True,
                          timeout=300, check=True)
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report['before'] == []
    assert public <= set(report['after']), sorted(public - set(report['after']))
    assert sorted(report['ran']) == sorted(public)
