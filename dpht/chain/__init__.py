"""A long tube as a chain of segments along the flow (docs/theory/chain.md): the segments and their
order (:mod:`dpht.chain.segments`) and the temperature field handed from one segment's outlet to
the next segment's particles (:mod:`dpht.chain.field`, its file :mod:`dpht.chain.files`)."""
