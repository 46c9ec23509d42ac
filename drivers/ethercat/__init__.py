"""EtherCAT master on pysoem (SOEM): the ``ethercat`` transport.

``master`` (:class:`~drivers.ethercat.master.EtherCATTransport`), ``al_status`` (AL states
and status codes in words), ``errors``.
"""
