"""How close TRPO's conjugate gradient runs to this machine's matrix-multiply speed.

TRPO's default Fisher product (``rl.trpo.gauss_newton_fisher_product``: one jvp and one
vjp of the policy on the batch) is most of a Pendulum iteration on a CPU. With the
reference's policy (two hidden layers of 100) nearly all its arithmetic is four
``samples x 100 x 100`` matrix products: the jvp's two through the middle layer (its weights'
tangent times the activations, its weights times the activations' tangent) and the vjp's two
(the middle layer's weight gradient, and the gradient passed back through it). This script
times, in one process, one after the other:

- ``products``: ``--products`` dependent Fisher products (as the conjugate gradient makes
  them), the vjp built once outside the loop, as TRPO builds it;
- ``matmuls``: the same number of rounds of only those four matrix products, at the same
  shapes, each round depending on the last (the floor no implementation of this product
  can go below on this machine, short of doing less arithmetic);

and prints their ratio and the GFLOP/s each reaches (counting the four products' 2 x
samples x hidden^2 flops each). A ratio near 1 says the Fisher product is already the
matrix products it must do; what is left is doing fewer of them (``fisher_subsample``, a
departure from the reference's Fisher on every sample).

    python benchmarks/fisher_roofline.py                       # Pendulum's 5,000 samples
    taskset -c 0 python benchmarks/fisher_roofline.py --json fisher.json   # one thread
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
from common import context, markdown_table, median_seconds, write_rows
from jax.flatten_util import ravel_pytree

from pngail_jax.networks import GaussianPolicy
from pngail_jax.rl.trpo import gauss_newton_fisher_product


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=5000, help="batch rows (25 x 200)")
    parser.add_argument("--hidden", type=int, default=100, help="width of both hidden layers")
    parser.add_argument("--obs-size", type=int, default=3, help="Pendulum-v1's 3")
    parser.add_argument("--products", type=int, default=10, help="the conjugate gradient's 10")
    parser.add_argument("--repeats", type=int, default=7, help="timed calls (median)")
    parser.add_argument("--json", help="write the rows here")
    return parser.parse_args(argv)


def fisher_products(args):
    """A compiled ``v -> v`` making ``args.products`` dependent Fisher products."""
    policy = GaussianPolicy(1, (args.hidden, args.hidden))
    keys = jax.random.split(jax.random.key(0), 2)
    obs = jax.random.normal(keys[0], (args.samples, args.obs_size))
    flat, unravel = ravel_pytree(policy.init(keys[1], obs))

    def run(flat, obs, v):
        product = gauss_newton_fisher_product(policy, unravel, flat, obs, 0.1)

        def step(_, x):  # normalised each round so that the rounds stay finite, as CG's do
            y = product(x)
            return y / jnp.linalg.norm(y)

        return jax.lax.fori_loop(0, args.products, step, v)

    program = jax.jit(run)
    return lambda: program(flat, obs, jnp.ones_like(flat) / flat.size**0.5)


def bare_matmuls(args):
    """A compiled loop of ``args.products`` rounds of the four matrix products alone."""
    keys = jax.random.split(jax.random.key(1), 4)
    rows = jax.random.normal(keys[0], (args.samples, args.hidden))  # activations
    weights = jax.random.normal(keys[1], (args.hidden, args.hidden)) / args.hidden**0.5
    tangent = jax.random.normal(keys[2], (args.hidden, args.hidden)) / args.hidden**0.5

    def step(_, carry):
        activations_tangent, weights_tangent = carry
        out_tangent = rows @ weights_tangent + activations_tangent @ weights  # the jvp's two
        back = out_tangent @ weights.T  # the vjp's pass back
        gradient = rows.T @ out_tangent / args.samples  # the vjp's weight gradient
        return back / jnp.linalg.norm(back), gradient / jnp.linalg.norm(gradient)

    program = jax.jit(lambda a, w: jax.lax.fori_loop(0, args.products, step, (a, w)))
    return lambda: program(rows, tangent)


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    flops = args.products * 4 * 2 * args.samples * args.hidden**2
    measured = {
        "products": median_seconds(fisher_products(args), repeats=args.repeats),
        "matmuls": median_seconds(bare_matmuls(args), repeats=args.repeats),
    }
    common = {**context(), "samples": args.samples, "hidden": args.hidden}
    rows = [
        {"name": f"fisher_roofline/{name}", **common, "products": args.products,
         "milliseconds": seconds * 1e3, "gflops_per_second": flops / seconds / 1e9,
         "over_matmuls": seconds / measured["matmuls"]}
        for name, seconds in measured.items()
    ]  # fmt: skip
    print(
        f"{args.products} Fisher products, {args.samples} samples, hidden {args.hidden} x "
        f"{args.hidden} ({context()['device']}, jax {jax.__version__})\n"
    )
    print(markdown_table(
        ["what", "ms", "GFLOP/s of the four matmuls", "time / matmuls alone"],
        [[row["name"].split("/")[1], f"{row['milliseconds']:.2f}",
          f"{row['gflops_per_second']:.1f}", f"{row['over_matmuls']:.2f}"] for row in rows],
        "lrrr",
    ))  # fmt: skip
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
