"""Integration tests with real processes on 127.0.0.1 (issue 16): a hostile flood of one channel
against ``millwatch serve``, SIGKILLed workers and gateways that must lose no block, and a worker
started before its gateway; and the parity of every surface with ``millwatch analyze`` (issue 24).

``hostile.py`` makes the hostile payloads (malformed and well-formed-but-wrong) from valid
blocks; ``live.py`` starts and stops the ``millwatch`` processes, reads their HTTP API and
compares stored results with ``millwatch analyze`` of the same scene; ``parity.py`` reads what
each surface (store file, REST, OPC UA, ``/metrics``, report CSV, Foxglove export) says about a
scene into a small typed table and lists where it differs from ``analyze --json``
(``test_parity.py``). Every wait is bounded in count and time; nothing listens or connects
anywhere but 127.0.0.1.
"""
