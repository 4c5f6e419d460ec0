"""Big stand-ins and oracles shared by more than one chapter (each in its own module).

Chapter packages import these by module (`from graders.oracles.bundle_adjust import ...`); an oracle
here never imports a chapter package. A stand-in a second chapter needs moves here (docs/ENGINE.md):

    camera        cv_project, cv_undistort (chapter 1)
    features      cv_corners, cv_fast, cv_dog, cv_sift_descriptors, cv_ratio_matches, cv_match (chapter 3)
    two_view      refine_essential, cv_recover_pose (chapter 2); SOLVERS of 6.13 (chapter 6)
    vo            standin_vo (chapter 6's 6.13)
    stereo        cv_block_matching, cv_sgbm (chapter 8)
    flow          cv_lucas_kanade, cv_pyramidal_lk, cv_farneback, cv_dis (chapter 9)
    sfm_standin   the OpenCV incremental SfM, PnP RANSAC, tracks (chapter 4)
    bundle_adjust the scipy BAL adjuster (chapters 4 and 5)
    colmap        COLMAP text model and database helpers (chapter 4)

The capstone (chapter 11) runs its pipeline on these, or on the learner's functions in their place.
"""
