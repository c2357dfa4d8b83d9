"""Headless matplotlib for the figures of scenarios and tools (never imported by ``import der``).

matplotlib is the optional ``plot`` extra: ``pip install -e '.[plot]'``. A command asked for a figure checks it
up front with ``require_matplotlib`` (a ValueError: the scenario contract's exit 2 with one line) instead of
running for minutes and then writing nothing.
"""
import sys

INSTALL = "pip install -e '.[plot]'"


def have_matplotlib():
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def require_matplotlib(option="--png"):
    """Raise ValueError (naming ``option``) if matplotlib is not installed."""
    if not have_matplotlib():
        raise ValueError(f"{option} needs matplotlib, which is not installed ({INSTALL})")


def pyplot(who):
    """``matplotlib.pyplot`` on the Agg backend, or None (with a one-line note on stderr) if matplotlib is not
    installed; ``who`` names the caller in that note."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print(f"{who}: matplotlib is not installed ({INSTALL}); no PNG written", file=sys.stderr)
        return None
    return plt


def bifurcation_diagram(branches, path, y, x=None, labels=None, title=None, y_label=None, x_label=None,
                        reference=None):
    """A PNG bifurcation diagram: summary ``y`` against the parameter for each ``der.continuation`` Branch,
    solid where the equilibrium is stable, dashed where it is not, special points marked (fold: o, bifurcation:
    s, hopf: ^). ``reference``: optional (xs, ys, label) curve drawn in grey. Returns ``path``, or None (with a
    note on stderr) if matplotlib is not installed (pip install -e '.[plot]')."""
    plt = pyplot("der.plotting.bifurcation_diagram")
    if plt is None:
        return None
    branches = list(branches)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    if reference is not None:
        ax.plot(reference[0], reference[1], color="0.6", lw=3, alpha=0.6, label=reference[2])
    markers = {"fold": "o", "bifurcation": "s", "hopf": "^"}
    for i, br in enumerate(branches):
        xs_name = x or br.parameter
        xs = [p[xs_name] for p in br.points]
        ys = [p[y] for p in br.points]
        stable = [p.get("stable") for p in br.points]
        color = f"C{i}"
        label = labels[i] if labels else f"branch {i}"
        # one segment per pair of points, styled by the stability of its later point
        for k in range(1, len(xs)):
            ax.plot(xs[k - 1:k + 1], ys[k - 1:k + 1], color=color, ls="-" if stable[k] else "--", lw=1.6,
                    label=label if k == 1 else None)
        for sp in br.special:
            ax.plot(sp[xs_name], sp[y], markers.get(sp["kind"], "x"), color=color, mfc="none", ms=8,
                    label=f"{sp['kind']} at {xs_name} = {sp[xs_name]:.5g}")
    ax.set_xlabel(x_label or (x or branches[0].parameter))
    ax.set_ylabel(y_label or y)
    if title:
        ax.set_title(title, fontsize=10)
    ax.plot([], [], color="k", ls="-", label="stable")
    ax.plot([], [], color="k", ls="--", label="unstable")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
