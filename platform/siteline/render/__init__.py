"""Point-cloud rendering: z-buffer splatting in torch (CPU or CUDA) of site-local points.

Names are imported from their modules; this front imports nothing, so ``siteline.records.params.render``
(the persisted knobs) does not pull in torch."""
