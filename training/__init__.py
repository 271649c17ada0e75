"""Training of the intention-net controllers (Gao et al., CoRL 2017) for the intention fleet.

Modules:

* `dataset`  -- memory-mapped reader of the recordings `eval record` writes (DATASET.md).
* `data`     -- episode split, balanced sampling, intention randomisation, photometric
                augmentation and batch assembly on top of `dataset`.
* `model`    -- DLM-Net, LPE-Net and the Non-Intention Net (small CNN or ResNet-50 backbone).
* `train`    -- the training command (`python -m training.train`).
* `export`   -- ONNX export with the model card and an onnxruntime agreement check
                (`python -m training.export`).
* `card`     -- the model card (ONNX metadata_props) the robot agent reads.

Run the commands from the repository root so that `training` is importable.
"""
