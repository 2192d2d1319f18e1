// SPDX-License-Identifier: GPL-3.0-or-later
// What a client generated from the served OpenAPI document with openapi-typescript's default
// options must accept under tsc --strict (tests/e2e/CMakeLists.txt, typed_client): a live change
// of one key, a run created from a partial scene, and a run summary's fields without checks for
// undefined (they are always present).
import type { components, paths } from "sphles-openapi";

type Patch =
  paths["/api/runs/{id}/parameters"]["patch"]["requestBody"]["content"]["application/json"];
type Create = paths["/api/runs"]["post"]["requestBody"]["content"]["application/json"];
type Summary = components["schemas"]["RunSummary"];

export const longer: Patch = { time: { end: 15 } };
export const created: Create = {
  scene: { case: "tgv3d", particles_per_side: 32, time: { end: 1 } },
};
export function describe(run: Summary): string {
  const id: string = run.id;
  const state: string = run.state;
  const progress: number = run.progress;
  return `${id} ${state} ${progress}`;
}
