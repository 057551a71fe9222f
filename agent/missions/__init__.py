"""Mission rooms' flight software: one subpackage per paper, each registering its own controller(s)
with `agent.controller.register` when imported. agent/catalogue.py imports every subpackage
(bus/discovery.py `import_all`) when a controller is looked up, so a new paper is a new room and no
central file is edited.
"""
