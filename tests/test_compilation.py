"""The compilation cache of the programs (``pngail_jax.storage.compilation``): a program that
calls back to the host, as MuJoCo's C engine does, is kept and read again by a fresh process."""

import json
import subprocess
import sys

import numpy as np

# A program with a host callback, compiled in a fresh process with the cache in argv[1]; the
# callback multiplies by argv[2], so a read entry shows whose callback it calls.
PROGRAM = """
import json, sys
import jax, jax.numpy as jnp, numpy as np
from pngail_jax.storage.compilation import enable_compilation_cache

enable_compilation_cache(sys.argv[1])
events = []
jax.monitoring.register_event_listener(lambda event, **_: events.append(event))
scale = float(sys.argv[2])

def host(x):
    return (np.asarray(x) * scale).astype(np.float32)

@jax.jit
def program(x):
    shape = jax.ShapeDtypeStruct(x.shape, x.dtype)
    return 2 * jax.pure_callback(host, shape, jnp.sin(x), vmap_method="broadcast_all")

values = jax.vmap(program)(jnp.arange(6.0).reshape(2, 3))
hits = events.count("/jax/compilation_cache/cache_hits")
print(json.dumps({"values": np.asarray(values).tolist(), "hits": hits}))
"""


def run_program(cache, scale: float) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", PROGRAM, str(cache), str(scale)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_program_with_host_callbacks_is_cached_and_calls_this_processes_callback(tmp_path):
    """Compiled once (a miss, one entry written), then read by two fresh processes (a hit
    each) with the same values, and with another callback behind the same program the values
    that callback gives: the entry holds the program, each process its own functions."""
    expected = 2 * np.sin(np.arange(6.0).reshape(2, 3)).astype(np.float32)
    first = run_program(tmp_path, 3.0)
    entries = list((tmp_path / "with-host-callbacks").iterdir())
    assert first["hits"] == 0 and len(entries) == 1, entries
    again, other = run_program(tmp_path, 3.0), run_program(tmp_path, 5.0)
    assert again["hits"] == 1 and other["hits"] == 1
    np.testing.assert_allclose(first["values"], 3 * expected, rtol=1e-6)
    assert again["values"] == first["values"]
    np.testing.assert_allclose(other["values"], 5 * expected, rtol=1e-6)
    assert list((tmp_path / "with-host-callbacks").iterdir()) == entries
