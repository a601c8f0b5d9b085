"""``python -m rtp``: the ``rtp`` command."""

from rtp.cli import main

raise SystemExit(main())
