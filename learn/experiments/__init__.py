"""`handskin experiment <name>`: the paper's Section 9 protocol and our own studies.

Each experiment writes one folder: ``report.md`` (tables beside the paper's numbers where they
exist, the exact command, seed, configuration and package versions), ``results.json`` and PNG
charts. ``--quick`` runs a small version in minutes (CI runs it on a tiny scale).
"""
