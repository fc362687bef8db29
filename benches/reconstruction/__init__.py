"""The pieces of benches/downstream.py, the E2VID-style reconstruction benchmark: the voxel grid
(`voxel_grid`), the EVREAL scores (`image_quality`), the training frames (`moving_images`) and
the recurrent U-Net (`network`, PyTorch). tests/test_downstream.py checks them."""
