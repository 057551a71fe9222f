"""Paper 002's flight software: the behavioural law (`sabatini`, sections 3.3-3.8) and its periodic
DRE gains (`dre`, section 3.4). Importing the package registers the controller "sabatini"
(missions/p002_sabatini/contract.py `CONTROLLER`); scipy is imported on use (the DRE solve).
"""
from swarmhil.missions.p002_sabatini.fsw import sabatini as _sabatini  # noqa: F401  (registers "sabatini")
