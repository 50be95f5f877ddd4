"""Kernel network emulation for live runs: every peer in its own network
namespace, joined to the launcher's router through a hub namespace that
routes between them and impairs the real packets of each peer's link.

- ``network``: the run's star of namespaces, built and torn down by the
  launcher (``KernelNetwork``), and what the machine must have for it.
- ``hub``: the process inside the hub namespace: it queues each peer's
  packets (iptables NFQUEUE) and releases, drops or duplicates them as the
  link model draws.
- ``scheduler``: those draws for packets, pure: a profile's link model
  applied per packet, the same model the bus shim applies per message.
- ``commands``: the ``ip``, ``nsenter``, ``iptables`` and ``sysctl`` calls.

Everything the run makes lives in namespaces that die with its processes,
and every process dies with the launcher, so nothing outlives a run, even a
launcher killed with SIGKILL.
"""
