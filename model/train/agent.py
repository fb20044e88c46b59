"""``python -m model.train.agent [torchrun options] -m model.train RUN_DIR …``: torchrun's elastic
agent for a run on this machine alone, listening on loopback only.

``torchrun --standalone`` serves its c10d store on every interface, whatever address it is given,
and the store takes no credentials: anyone who reaches the machine could read and write the run's
keys. Here the rendezvous is :class:`LoopbackRendezvous`: the agent binds a socket on 127.0.0.1
itself and hands it to the store (``master_listen_fd``), the ranks reach that store as clients
(``TORCHELASTIC_USE_AGENT_STORE``), and gloo (and NCCL's bootstrap) listen on the loopback
interface. Everything else — starting, watching and stopping the ranks, their logs, the failure
summary — is torchrun's own. Multi-machine runs use torchrun's c10d rendezvous across the nodes,
which needs a trusted network.
"""

from __future__ import annotations

import os
import socket
import sys
from datetime import timedelta

from torch.distributed import PrefixStore, Store, TCPStore
from torch.distributed.elastic.multiprocessing.errors import record
from torch.distributed.elastic.rendezvous import (
    RendezvousHandler,
    RendezvousInfo,
    RendezvousParameters,
    RendezvousStoreInfo,
    rendezvous_handler_registry,
)
from torch.distributed.run import parse_args, run

BACKEND = "loopback"
HOST = "127.0.0.1"
LOOPBACK_INTERFACE = "lo"  # Linux's
STORE_TIMEOUT = timedelta(minutes=10)


class LoopbackRendezvous(RendezvousHandler):
    """A rendezvous of one node: a TCPStore served on a socket this process bound on 127.0.0.1."""

    def __init__(self, params: RendezvousParameters) -> None:
        self.run_id = params.run_id
        self._store: TCPStore | None = None

    def get_backend(self) -> str:
        return BACKEND

    @property
    def use_agent_store(self) -> bool:
        return True  # the ranks' env:// rendezvous connects to this store; none serves its own

    def next_rendezvous(self) -> RendezvousInfo:
        if self._store is None:
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.bind((HOST, 0))
            listener.listen(socket.SOMAXCONN)
            port = listener.getsockname()[1]
            # detach(): the store owns the descriptor from here on (and closes it).
            self._store = TCPStore(HOST, port, None, True, STORE_TIMEOUT, wait_for_workers=False,
                                   multi_tenant=True, master_listen_fd=listener.detach())
        store: Store = PrefixStore(self.run_id, self._store)
        return RendezvousInfo(store, 0, 1, RendezvousStoreInfo(HOST, self._store.port))

    def is_closed(self) -> bool:
        return False

    def set_closed(self) -> None:
        pass

    def num_nodes_waiting(self) -> int:
        return 0

    def get_run_id(self) -> str:
        return self.run_id

    def shutdown(self) -> bool:
        return True


@record  # torchrun's entry point's wrapper: a rank's failure ends in torchrun's failure summary
def main(argv: list[str] | None = None) -> None:
    """Run torchrun with ``argv`` (its options, then the module and its arguments) on one node,
    its rendezvous replaced by :class:`LoopbackRendezvous` whatever ``argv`` says."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    args.standalone = False
    args.nnodes = "1"
    args.rdzv_backend, args.rdzv_endpoint = BACKEND, f"{HOST}:0"
    rendezvous_handler_registry.register(BACKEND, LoopbackRendezvous)
    # The ranks inherit these: gloo's pair listeners and NCCL's bootstrap sockets bind to the
    # loopback interface's address, not to what the host name resolves to.
    os.environ["GLOO_SOCKET_IFNAME"] = os.environ["NCCL_SOCKET_IFNAME"] = LOOPBACK_INTERFACE
    run(args)


if __name__ == "__main__":
    main()
