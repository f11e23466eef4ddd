// The farm's client commands: submit, status, watch, fetch, cancel, pause, resume, priority,
// workers, health (cli/farm.h runs them).
#include "cli/commands.h"
#include "client/commands.h"
#include "farm/auth.h"
#include "farm/tags.h"

namespace rf::cli {

void add_progress_option(CLI::App* c, std::string* progress) {
  c->add_option("--progress", *progress,
                "text (default), or openjd: Open Job Description progress lines "
                "(openjd_progress: PERCENT, openjd_status: TEXT) for job runners")
      ->envname("RAYFARM_PROGRESS")
      ->check(CLI::IsMember({"text", "openjd"}));
}

void add_client_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out) {
  auto add_addr = [&](CLI::App* c, double* timeout) {
    c->add_option("--coordinator", shared.coordinator,
                  "coordinator address (default: $RAYFARM_COORDINATOR, else 127.0.0.1:7070)");
    c->add_option("--timeout", *timeout,
                  "give up after this many seconds (watch: this long without an answer); calls "
                  "answered UNAVAILABLE are retried until then (default 300)")
        ->check(finite_in(0.001, 1e9));
    add_credential_options(*c, shared);
  };
  struct Args {
    OverrideArgs overrides;
    SubmitArgs submit;
    std::string job, fetch_dir, fetch_frames, retry_frames, requeue_scene, health_addr;
    bool json = false, services = false, force = false, wait = false;
    // Each command its own: CLI11 writes $RAYFARM_PROGRESS into every command's unset
    // --progress, parsed or not, so a shared one would let it overwrite a flag given.
    std::string progress = "text", submit_progress = "text";
    StatusPage page;
    std::optional<FrameNumber> fetch_frame, logs_frame;
    std::string logs_task;
    uint32_t logs_limit = 0;
    FetchOutput fetch;
    double timeout = 300;
    int priority = 0;
  };
  auto a = std::make_shared<Args>();

  // Read when the command runs, after parsing, so a bad token file is reported as such.
  auto ep = [&shared, a] {
    return Endpoint{
        shared.coordinator,
        load_client_credentials(shared.token_file, shared.tls_ca, shared.tls_cert, shared.tls_key),
        a->timeout};
  };

  auto* submit = app.add_subcommand("submit", "submit a job; prints its id");
  add_addr(submit, &a->timeout);
  submit
      ->add_option("scene", a->submit.scene, "scene file, or a per-frame pattern (shot.####.json)")
      ->required();
  add_override_options(*submit, a->overrides);
  submit->add_option("--frames", a->submit.frames,
                     "frames, Open Job Description syntax (1-10:2,15)");
  submit->add_option("--priority", a->submit.priority, "higher runs first")
      ->check(finite_in(-1e9, 1e9));
  submit->add_option("--name", a->submit.name, "job name (default: the scene's file name)");
  submit->add_option("--tile-size", a->submit.tile_size, "tile size in pixels")
      ->check(finite_in(8, 4096));
  submit->add_option("--build-id", a->submit.build_id,
                     "merge results of this worker build only (default: the first result's)");
  submit
      ->add_option("--require", a->submit.required_tags,
                   "a worker tag the job needs: NAME, NAME=VALUE or NAME>=NUMBER (repeatable; "
                   "pool=NAME picks a worker pool)")
      ->check([](const std::string& r) { return requirement_problem(r); });
  submit->add_flag("--json", a->json, "print {\"job_id\": ...}; with --wait, watch's JSON lines");
  submit->add_flag("--wait", a->wait,
                   "then watch the job until it ends (exit status as watch's: 0 completed)");
  add_progress_option(submit, &a->submit_progress);
  out.push_back({submit, [a, ep] {
                   a->submit.overrides = overrides_of(a->overrides);
                   std::optional<WatchOutput> wait;
                   if (a->wait) wait = WatchOutput{a->json, a->submit_progress == "openjd"};
                   return cmd_submit(ep(), a->submit, a->json, wait);
                 }});

  auto* bundle = app.add_subcommand(
      "bundle", "the files a submit of SCENE uploads, with their SHA-256 and size (no upload)");
  bundle->add_option("scene", a->submit.scene, "scene file, or a per-frame pattern")->required();
  bundle->add_option("--frames", a->submit.frames, "the frames of a per-frame pattern");
  bundle->add_flag("--json", a->json, "{\"scene\", \"dir\", \"files\": [{path, sha256, bytes}]}");
  out.push_back({bundle, [a] { return cmd_bundle(a->submit.scene, a->submit.frames, a->json); }});

  auto* status = app.add_subcommand("status", "all jobs (or one), one line each");
  add_addr(status, &a->timeout);
  status->add_option("job", a->job, "one job");
  status->add_flag("--json", a->json, "machine-readable");
  status->add_option("--limit", a->page.limit, "at most this many jobs (default: all)")
      ->check(finite_in(1, 1e9));
  status->add_option("--after", a->page.after, "the jobs after this one");
  out.push_back({status, [a, ep] { return cmd_status(ep(), a->job, a->json, a->page); }});

  auto* watch = app.add_subcommand("watch", "follow a job until it ends (exit 0: completed)");
  add_addr(watch, &a->timeout);
  watch->add_option("job", a->job, "job id")->required();
  watch->add_flag("--json", a->json, "JSON lines: one per frame update, then the job's end");
  add_progress_option(watch, &a->progress);
  out.push_back({watch, [a, ep] {
                   return cmd_watch(ep(), a->job, {a->json, a->progress == "openjd"});
                 }});

  auto* fetch = app.add_subcommand("fetch", "write a job's frames (EXR + PNG), also mid-job");
  add_addr(fetch, &a->timeout);
  fetch->add_option("job", a->job, "job id")->required();
  fetch
      ->add_option("-o,--output", a->fetch_dir,
                   "output directory (JOB.####.exr in it), or a frame template ending in .exr "
                   "(shot.####.exr, shot.%04d.exr)")
      ->required();
  auto* fetch_frame = fetch->add_option("--frame", a->fetch_frame, "only this frame")
                          ->check(finite_in(-2147483648.0, 2147483647.0));
  fetch->add_option("--frames", a->fetch_frames, "only these frames (1-24, 1-24:2, 1,5,9)")
      ->excludes(fetch_frame);
  fetch->add_option("--exposure", a->fetch.exposure, "PNG exposure in stops")
      ->check(finite_in(-64, 64));
  fetch->add_flag("!--no-png", a->fetch.png, "no PNG preview beside each EXR");
  fetch->add_flag("--half", a->fetch.half, "half-float EXR channels (half the file)");
  fetch->add_flag("--json", a->fetch.json, "one JSON line per frame written (files, figures)");
  out.push_back({fetch, [a, ep] {
                   return cmd_fetch(
                       ep(), a->job, a->fetch_dir,
                       a->fetch_frame ? std::to_string(*a->fetch_frame) : a->fetch_frames,
                       a->fetch);
                 }});

  auto* cancel = app.add_subcommand("cancel", "cancel a job");
  add_addr(cancel, &a->timeout);
  cancel->add_option("job", a->job, "job id")->required();
  out.push_back({cancel, [a, ep] { return cmd_cancel(ep(), a->job); }});

  for (bool pause : {true, false}) {
    auto* c = app.add_subcommand(
        pause ? "pause" : "resume",
        pause ? "pause a job: no new leases (those in flight finish)" : "resume a paused job");
    add_addr(c, &a->timeout);
    c->add_option("job", a->job, "job id")->required();
    out.push_back({c, [a, ep, pause] { return cmd_pause(ep(), a->job, pause); }});
  }

  auto* priority = app.add_subcommand("priority", "change a job's priority (higher runs first)");
  add_addr(priority, &a->timeout);
  priority->add_option("job", a->job, "job id")->required();
  priority->add_option("priority", a->priority, "the new priority")
      ->required()
      ->check(finite_in(-1e9, 1e9));
  out.push_back({priority, [a, ep] { return cmd_priority(ep(), a->job, a->priority); }});

  auto* retry = app.add_subcommand(
      "retry", "run a failed or cancelled job's unfinished frames again (failure counts afresh)");
  add_addr(retry, &a->timeout);
  retry->add_option("job", a->job, "job id")->required();
  retry->add_option("--frames", a->retry_frames,
                    "only these frames (1-24, 1-24:2, 1,5,9); the job's other unfinished frames "
                    "are held until a later retry");
  out.push_back({retry, [a, ep] { return cmd_retry(ep(), a->job, a->retry_frames); }});

  auto* requeue = app.add_subcommand(
      "requeue",
      "render a job's frames again from scratch (after fixing the scene: --scene), with its seed "
      "and settings; an ended job runs again");
  add_addr(requeue, &a->timeout);
  requeue->add_option("job", a->job, "job id")->required();
  requeue->add_option("--frames", a->retry_frames, "the frames (3, 1-24, 1-24:2, 1,5,9)")
      ->required();
  requeue->add_option("--scene", a->requeue_scene,
                      "the fixed scene (a file, or a per-frame pattern such as shot.####.json): "
                      "its bundle is uploaded and becomes the job's next scene version for these "
                      "frames; it must keep the job's resolution and passes");
  out.push_back(
      {requeue, [a, ep] { return cmd_requeue(ep(), a->job, a->retry_frames, a->requeue_scene); }});

  auto* del =
      app.add_subcommand("delete", "remove an ended job and its files (its scene blobs stay)");
  add_addr(del, &a->timeout);
  del->add_option("job", a->job, "job id")->required();
  del->add_flag("--force", a->force, "also a queued or running job (its work in flight is lost)");
  out.push_back({del, [a, ep] { return cmd_delete(ep(), a->job, a->force); }});

  auto* logs = app.add_subcommand(
      "logs", "a job's task attempts: worker, times, outcome and the worker's log lines");
  add_addr(logs, &a->timeout);
  logs->add_option("job", a->job, "job id")->required();
  auto* logs_frame = logs->add_option("--frame", a->logs_frame, "only this frame")
                         ->check(finite_in(-2147483648.0, 2147483647.0));
  logs->add_option("--task", a->logs_task, "only this task (JOB/FRAME/PASS/TILE)")
      ->excludes(logs_frame);
  logs->add_option("--limit", a->logs_limit, "the most recent attempts (default 100)")
      ->check(finite_in(1, 10000));
  logs->add_flag("--json", a->json, "machine-readable output");
  out.push_back({logs, [a, ep] {
                   return cmd_logs(ep(), a->job, a->logs_frame, a->logs_task, a->logs_limit,
                                   a->json);
                 }});

  auto* workers = app.add_subcommand("workers", "list the registered workers");
  add_addr(workers, &a->timeout);
  workers->add_flag("--json", a->json, "machine-readable output");
  out.push_back({workers, [a, ep] { return cmd_workers(ep(), a->json); }});

  auto* health = app.add_subcommand("health", "check a coordinator's gRPC health service");
  health->add_option("--coordinator", shared.coordinator,
                     "coordinator address (default: $RAYFARM_COORDINATOR, else 127.0.0.1:7070)");
  health->add_option("--tls-ca", shared.tls_ca,
                     "CA of the coordinator's TLS certificate (default: $RAYFARM_TLS_CA; none: "
                     "plaintext)");
  health->add_option("address", a->health_addr, "HOST:PORT (default: as --coordinator)");
  health->add_flag("--services", a->services, "also list its services (server reflection)");
  health->add_flag("--json", a->json, "{\"address\": ..., \"status\": ..., \"services\": [...]}");
  out.push_back({health, [a, &shared] {
                   Endpoint e{a->health_addr.empty() ? shared.coordinator : a->health_addr,
                              load_client_credentials("", shared.tls_ca, "", "")};
                   e.creds.token.clear();  // the health service takes none
                   return cmd_health(e, a->services, a->json);
                 }});
}

void add_credential_options(CLI::App& c, SharedOptions& shared) {
  c.add_option("--token-file", shared.token_file,
               "file holding the token (default: $RAYFARM_TOKEN_FILE, else $RAYFARM_TOKEN)");
  c.add_option("--tls-ca", shared.tls_ca,
               "CA of the coordinator's TLS certificate, PEM (default: $RAYFARM_TLS_CA; none: "
               "plaintext)");
  c.add_option("--tls-cert", shared.tls_cert,
               "this client's TLS certificate for mutual TLS, PEM (default: $RAYFARM_TLS_CERT)");
  c.add_option("--tls-key", shared.tls_key,
               "the key of --tls-cert, PEM (default: $RAYFARM_TLS_KEY)");
}

}  // namespace rf::cli
