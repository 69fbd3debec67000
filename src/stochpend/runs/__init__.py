"""A run's life: build, check and execute (:mod:`.lifecycle`, :mod:`.simulate`), the
discretisation-bias estimate (:mod:`.bias`, public as ``stochpend.bias``) and the accuracy
target (:mod:`.multilevel`), the resource checks (:mod:`.resources`), checkpoints
(:mod:`.checkpoint`), sweeps over parameters on threads or Dask (:mod:`.sweep`, public as
``stochpend.sweep``; :mod:`.dask`), and the reduced dynamics (:mod:`.reduced`)."""
