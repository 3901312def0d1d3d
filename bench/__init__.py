"""Ground truth, metrics and every benchmark (``pibr demo``, ``pibr evaluate``, ``pibr bench ...``).

The modules form a line: :mod:`.results`, :mod:`.metrics`, :mod:`.windows` and :mod:`.variants`
at the bottom; :mod:`.simulation` (a server and a client in one process, on the server's own
session pipeline), :mod:`.groundtruth`, :mod:`.processes` and :mod:`.plots` on them; one module
per benchmark above those; :mod:`.cli` (what each command takes) and :mod:`.commands` (what it
does) at the top. Nothing else imports this package.
"""
