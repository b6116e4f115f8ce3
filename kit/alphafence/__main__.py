from alphafence.cli import main

raise SystemExit(main())
