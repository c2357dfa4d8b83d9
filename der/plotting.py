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
