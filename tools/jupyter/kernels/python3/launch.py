"""Start ipykernel as the standard ``python3`` kernel does, without its notice about TCP.

The Makefile puts ``tools/jupyter`` on ``JUPYTER_PATH``, so the book build,
``make notebooks`` and ``make lab`` start the book's pages with this kernel
(jupyter_client runs it with the Python that starts it). It is ipykernel's own
kernel, except that its log drops the warning that a kernel "is running over
TCP without encryption", printed by every kernel that a local client starts
over the loopback interface, which would otherwise fill the build log with one
identical warning per page. Every other message of the kernel is kept.

Its figures are shown as PNG and also kept as PDF: the HTML book shows the PNG,
the PDF book prints the vector copy (myst-nb prefers ``application/pdf`` for
LaTeX), so that a printed figure's lines and text stay sharp at any size.
"""

import logging

from ipykernel.kernelapp import IPKernelApp


class _DropPlainTcpNotice(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "running over TCP without encryption" not in record.getMessage()


class BookKernelApp(IPKernelApp):
    def initialize(self, argv=None):
        self.config.InlineBackend.figure_formats = {"png", "pdf"}
        super().initialize(argv)

    def init_sockets(self):
        self.log.addFilter(_DropPlainTcpNotice())
        super().init_sockets()


if __name__ == "__main__":
    BookKernelApp.launch_instance()
