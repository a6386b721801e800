"""The report files of run folders: one typed model per file, its name, its schema
(``schemas/*.schema.json``), a writer and a reader.

=====================  ==============================  ==========================================
module                 file                            written by
=====================  ==============================  ==========================================
``script_run``         ``run_report.json``             ``recon run``
``autoscan``           ``autoscan_report.json``        ``recon autoscan``
``capture``            ``capture_report.json``         ``recon capture``
``register``           ``report.json``                 ``recon register`` (and every registration)
``evaluation``         ``<name>_evaluation.json``      ``recon evaluate``, a script's ``<evaluate>``
=====================  ==============================  ==========================================

Each module has ``write(folder, model) -> Path`` (atomically, :mod:`recon_cli.outputs`) and
``read(folder_or_path) -> model``, which reads through the guarded JSON reader
(:mod:`recon_cli.inputs.jsonfile`) and checks the file against its schema; a file that
cannot be read or does not match is one :class:`~recon_cli.errors.MetadataError` line naming
the file and the key. ``session.json`` and ``scan.json`` of a scan store are
:mod:`recon_cli.reconstruction.metadata`'s. :mod:`.codec` turns models into JSON and back,
:mod:`.files` writes and reads one file.

This package is a low layer: it imports only :mod:`recon_cli.inputs`,
:mod:`recon_cli.outputs` and :mod:`recon_cli.errors`.
"""
