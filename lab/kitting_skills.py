"""One memory that knows each skill's course, told the skill or inferring it (docs/kitting.md, "A
memory that knows each skill's course"). Written before it was run.

Hypothesis: one network for every skill, told the skill by a one-hot cue (observed and fed to the
prior as the context input W_C c), scored by a course term (the skill's offline recall from its
own start) and a dynamics term (online recall under the skill's cue), each whitened by the skill's
own spreads per step (`models.skill_context`), with, not told, a posterior over the skills updated
every step (forgetting 0.01) and the fault energy the step's surprise under the skills still
plausible (`models.skill_posterior`), reaches on every run-wise split 0-2 (three trainings each,
delta 0.5 s, the benchmark's protocol and code): not told mean AUROC over skills 3-5 >= 0.97 with
no_object >= 0.90; told >= 0.98; >= 85 % detected and <= 2 % of normal test segments flagged at
the served 1 % threshold; median delay <= 100 ms. Adopted if all hold on every split.

Rows, not told and told: the memory (course + dynamics: the primary), its course alone, its
dynamics alone, the demonstrations' mean course with its dynamics (what the network's course adds
over a template); beside them template_likelihood (each skill's mean course and own spreads, the
most probable skill step by step), template_told, nasm_one and nasm_one_online.

Confounds: the no_object day, anomalies of every run, the 1 % threshold on 36-40 peaks, the silent
tactile pad, per-skill spreads from 7-14 segments; ε and the shrinkage fixed before any run.

    python -m lab.kitting_skills "$SCHEME" --splits 0 1 2 --seeds 3 --cache /work/data/cache/kitting_skills
"""
