"""Text for people: the paper's equation numbers (:mod:`.equations`, public as
``stochpend.paper``'s names), docstrings that cite them (:mod:`._docs`), notation and
number formats (:mod:`._notation`), terminal escaping (:mod:`._terminal`), warnings
(:mod:`._warnings`) and the progress protocol (:mod:`.progress`). The lowest layer."""
