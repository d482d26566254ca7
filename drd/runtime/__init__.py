"""The Mission Executive's core: runs a compiled statechart, pure, with an injected clock.

`Interpreter` steps a `dsl.statechart.Statechart` with run-to-completion semantics; the
Resource Controller Manager (`drd.rcm`) decides grants; components follow an explicit
lifecycle (`drd.runtime.component`). Nothing here sleeps, reads the wall clock or does I/O:
the embedded executor and the daemon drive it.
"""
