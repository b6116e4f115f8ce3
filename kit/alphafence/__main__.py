"""``python -m alphafence``: the same command as the ``alphafence`` console script."""

from alphafence.cli import main

raise SystemExit(main())
