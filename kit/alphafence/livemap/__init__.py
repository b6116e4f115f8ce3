"""The live map: an observer of the monitor that keeps the latest state and a bounded queue
per page (``observer``), the messages it sends (``view``), its web server (``server``, aiohttp,
GET only, a token off loopback) and its page (``page``)."""
