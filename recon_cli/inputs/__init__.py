"""Every file a user gives recon is read here, through one guarded reader per kind:

* :mod:`.yamlfile` — YAML (station, camera, realism, batch, calibration and cell files):
  size limit, no aliases, no tags, the line of every key;
* :mod:`.schema` — one declarative schema per YAML file kind: known keys (unknown ones
  named with file:line), types, finite numbers inside documented ranges;
* :mod:`.numbers` — the number checks the schemas (and adapters) share;
* :mod:`.files` — the guard every reader starts with: a regular file within its
  size limit, checked before it is opened and opened without blocking;
* :mod:`.jsonfile` — JSON of scan stores, recordings and run folders: no NaN, bounded
  nesting and integers, no duplicate keys;
* :mod:`.images` — PNG/JPEG reads with the header's size checked before decoding;
* :mod:`.meshes` — OBJ/PLY/STL reads with declared sizes checked before loading and
  NaN, infinite or degenerate geometry refused.

A refusal is one :class:`~recon_cli.errors.InputError` / :class:`~recon_cli.errors.FileError`
line naming the file (and line), the value, the allowed range and what to do.
"""
