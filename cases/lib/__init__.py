"""The study runner, its evaluators and report, and the cross-validation table (`cases study`, `cases crossval`)."""
