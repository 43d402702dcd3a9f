"""The command-line verbs: ``snakekit grade`` (:mod:`.grade`) and ``snakekit lab`` (:mod:`.lab`)."""
