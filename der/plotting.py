"""Headless matplotlib for the figures of scenarios and tools (never imported by ``import der``)."""
import sys


def pyplot(who):
    """``matplotlib.pyplot`` on the Agg backend, or None (with a one-line note on stderr) if matplotlib is not
    installed; ``who`` names the caller in that note."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print(f"{who}: matplotlib is not installed (pip install -e '.[plot]'); no PNG written", file=sys.stderr)
        return None
    return plt
