"""``python -m orchestrator.cli``: the ``hpcosim`` command line."""

from orchestrator.cli import main

raise SystemExit(main())
