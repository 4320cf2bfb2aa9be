"""``python -m lapwrench``: the ``lapwrench`` command (:func:`lapwrench.cli.main`), the same entry point as
the console script; its stop signals are handled from the first import on (see :mod:`lapwrench.cli`)."""

from lapwrench.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
