"""
The soak's machinery: test code, not shipped in the package.

The line with its log (:mod:`.line`), the driver that runs the bus master on it
(:mod:`.runner`), the independent oracle (:mod:`.oracle`) and the deliberately broken bridges
that prove the oracle catches what it must (:mod:`.broken`). The tests import it with
``test/`` on ``sys.path`` (``test/conftest.py``); the benches put ``test/`` there themselves.
"""
