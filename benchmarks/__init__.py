"""Speed benchmarks (``illusion-studio bench …``) and what they run against: the click and
generation benchmarks drive the whole app (HTTP server, database, media store); the segmenter
and prefilter ones run in process, the latter against ``vlm_server``, a stand-in
OpenAI-compatible server that the VLM tests use too."""
