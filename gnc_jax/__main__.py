"""`python -m gnc_jax …` is the same as the `gnc-jax` command."""

from gnc_jax.cli import main

raise SystemExit(main())
