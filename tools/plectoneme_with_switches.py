"""scenarios/plectoneme.py with the contact solver's module switches set, for side-by-side runs (docs/contact.md 9.6).

    python tools/plectoneme_with_switches.py [--set NAME=VALUE ...] -- [plectoneme.py's arguments]

NAME is a module constant of der/solvers/implicit.py (e.g. CONTACT_SYMMETRIC, CONTACT_ARC_EVERY_FRACTION,
EXACT_CONTACT_BELOW) or of der/contact/reorder.py (CHOLESKY_RETRY_AFTER); VALUE is parsed as the constant's own
type (0/1 for a switch). Runs the scenario in this process (its output and exit code), e.g.

    python tools/plectoneme_with_switches.py --set CONTACT_ARC_EVERY_FRACTION=0 -- --turns 6 --sweep 24 --json
"""
import os
import runpy
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def apply_switches(items):
    """Set each NAME=VALUE of ``items`` on der/solvers/implicit.py or der/contact/reorder.py (VALUE in the
    constant's own type; 0/1 for a switch)."""
    import der.contact.reorder as reorder
    import der.solvers.implicit as implicit

    for item in items:
        name, _, value = item.partition("=")
        module = implicit if hasattr(implicit, name) else reorder if hasattr(reorder, name) else None
        if module is None:
            raise SystemExit(f"no switch {name} in der/solvers/implicit.py or der/contact/reorder.py")
        old = getattr(module, name)
        setattr(module, name, bool(int(value)) if isinstance(old, bool) else type(old)(float(value)))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    rest = argv.index("--") if "--" in argv else len(argv)
    own, scenario_args = argv[:rest], argv[rest + 1:]
    apply_switches([own[i + 1] for i, a in enumerate(own) if a == "--set"])
    sys.argv = ["plectoneme.py"] + scenario_args
    runpy.run_path(os.path.join(HERE, "..", "scenarios", "plectoneme.py"), run_name="__main__")


if __name__ == "__main__":
    main()
