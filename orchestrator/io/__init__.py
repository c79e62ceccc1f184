"""Input and output every command shares: results written whole or not at all (:mod:`.output`), archives and
TOML and tables read as hostile (:mod:`.archives`, :mod:`.tomlfile`, :mod:`.tables`), progress of long work
(:mod:`.progress`) and a run's figures (:mod:`.plots`). Nothing here knows a positioning system or a command."""
