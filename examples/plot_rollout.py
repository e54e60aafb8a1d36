#!/usr/bin/env python3
"""Plot a lockstep rollout file: the first environments' joint positions over time, and the mean reward.

The mean reward is plotted when the file has one.

    plot_rollout.py FILE.h5 OUT.png [--envs 4] [--dofs name1,name2]

Reads the dataset "q" [T, N, nq] (column names: the attribute "q_names";
without --dofs, the columns of 1-DOF joints, those also named in the
attribute "dof_names", at most 12) and "reward" [T, N] if present. Row t
is the state after env step t, at time (t + 1) * "dt" * "control_steps"
(or with "dt" alone, or the step number t + 1 without "dt"). Works on an interrupted file too (opened with swmr=True; only the
steps every step dataset holds are plotted). Needs h5py and matplotlib
(Debian: python3-h5py, python3-matplotlib).
"""
import argparse
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 (after choosing the backend)

MAX_DEFAULT_COLUMNS = 12  # without --dofs, plot at most this many columns of q


def text(value):
    return value.decode() if isinstance(value, bytes) else str(value)


def whole_steps(f):
    """The steps every step dataset holds: the smallest extent along T of
    the datasets that grow (unlimited first dimension)."""
    extents = [d.shape[0] for d in f.values()
               if isinstance(d, h5py.Dataset) and d.maxshape and d.maxshape[0] is None]
    return min(extents) if extents else 0


def step_seconds(attrs):
    if "dt" not in attrs:
        return None
    return float(attrs["dt"]) * float(attrs.get("control_steps", 1))


def choose_columns(names, dof_names, wanted):
    """Indices of the q columns to plot: those named in --dofs; else the
    joint positions of 1-DOF joints (the q columns also named in dof_names:
    a free or spherical joint's columns are not), else the first columns."""
    if wanted is None:
        joints = [k for k, name in enumerate(names) if name in dof_names]
        return (joints or list(range(len(names))))[:MAX_DEFAULT_COLUMNS]
    columns = []
    for name in wanted.split(","):
        if name not in names:
            sys.exit(f"plot_rollout.py: no q column named {name!r}; columns: {', '.join(names)}")
        columns.append(names.index(name))
    return columns


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", help="a rollout file (.h5)")
    parser.add_argument("out", help="the picture to write (.png)")
    parser.add_argument("--envs", type=int, help="environments to plot, the first ones (default: 4, or all if fewer)")
    parser.add_argument("--dofs", help="comma-separated q column names (attribute q_names) to plot")
    args = parser.parse_args()

    with h5py.File(args.file, "r", swmr=True) as f:
        if "q" not in f:
            sys.exit(f"plot_rollout.py: {args.file} has no dataset 'q'")
        complete = int(f.attrs.get("complete", 0)) == 1
        steps = whole_steps(f)
        q = f["q"][:steps]
        if q.ndim == 2:  # [T, nq]: a single environment
            q = q[:, None, :]
        nq = q.shape[2]
        names = [text(n) for n in f.attrs["q_names"]] if "q_names" in f.attrs else [f"q[{k}]" for k in range(nq)]
        dof_names = {text(n) for n in f.attrs.get("dof_names", [])}
        reward = f["reward"][:steps] if "reward" in f else None
        seconds = step_seconds(f.attrs)

    columns = choose_columns(names, dof_names, args.dofs)
    envs = min(4, q.shape[1]) if args.envs is None else args.envs
    if not 1 <= envs <= q.shape[1]:
        sys.exit(f"plot_rollout.py: --envs must be in [1, {q.shape[1]}] (the file has {q.shape[1]} environments)")
    x = [(t + 1) * seconds for t in range(steps)] if seconds else list(range(1, steps + 1))  # row t: after step t
    x_label = "time [s]" if seconds else "step"

    rows = envs + (reward is not None)
    fig, axes = plt.subplots(rows, 1, sharex=True, figsize=(11, 2.2 * rows + 1), squeeze=False)
    for env in range(envs):
        ax = axes[env, 0]
        ax.set_prop_cycle(color=plt.cm.tab20.colors)  # 20 distinct colours
        for k in columns:
            ax.plot(x, q[:, env, k], label=names[k], linewidth=1)
        ax.set_ylabel(f"env {env}: q")
        ax.grid(True, alpha=0.3)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="center right", fontsize="small")
    if reward is not None:
        ax = axes[-1, 0]
        ax.plot(x, reward.reshape(steps, -1).mean(axis=1), color="black", linewidth=1)
        ax.set_ylabel("mean reward")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel(x_label)

    state = "complete" if complete else f"interrupted: {steps} whole steps"
    fig.suptitle(f"{args.file} ({state})")
    fig.tight_layout(rect=(0, 0, 0.86, 1))  # the right-hand side holds the legend
    fig.savefig(args.out, dpi=100)


if __name__ == "__main__":
    main()
