"""Head traces as files and names (the :class:`~pibr.protocol.trace.HeadTrace` type itself is
the protocol's): :mod:`.loading` (by name or file, the built-in recordings in ``data/``),
:mod:`.canonical` (pibr's own CSV), :mod:`.importers` (other formats, converted once at the
edge), :mod:`.synthesis` (synthetic motion), :mod:`.placement` (where a window goes in a
scene) and :mod:`.lines` (the line-by-line reading they share)."""
