"""The analysis engine of ``avard analyze`` (and of explain, web and the benchmarks).

- ``engine``: one pass (or a few) over a record into the OADEV or cascade accumulators and
  the Welch spectrum, then the noise fit per channel (``analyze``, ``analyze_stream``).
- ``spectrum``: the streaming Welch PSD and the sinusoid finder.
- ``psd``: the PSD's confidence band and the white density read from it (``--psd``).
- ``results``: ``Analysis`` and ``ChannelAnalysis`` and their ``--json`` shape.
- ``formats``: the text table, csv files and kalibr's yaml.
"""
