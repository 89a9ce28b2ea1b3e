"""The ``dg16m`` subcommands of :mod:`dg16m_env` (registered through the ``dg16m.commands``
entry points in ``pyproject.toml``; :mod:`dg16m_core.cli` discovers them): ``dg16m benchmark``
(:mod:`.benchmark`), ``dg16m evaluate`` and ``dg16m submission`` (:mod:`.evaluate`), and
``dg16m sim`` (:mod:`.sim`).

Layer rule: the top layer. Command modules parse arguments, call the layers below and print;
nothing in :mod:`dg16m_env` imports them, and they hold no logic a library user would need.
"""
