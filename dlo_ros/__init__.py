"""dlo_ros: static shape of deformable linear objects (Hirai & Wakamatsu string model)."""
